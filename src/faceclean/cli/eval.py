"""``faceclean eval [--data DIR] [--json OUT] [--markdown OUT] [--quick]``.

Runs the evaluation protocol of faceclean.evaluation.evaluate (leave one source out; 30, 60, 120 fps
and webcam timing; every method) and prints the 60 fps table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "evaluate every cleaner on takes from sources the learned models never saw"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", help="folder of clean takes, one subfolder per source")
    p.add_argument("--json", metavar="OUT", help="write every figure as JSON")
    p.add_argument("--markdown", metavar="OUT", help="write the RESULTS tables (markdown)")
    p.add_argument(
        "--models",
        nargs="+",
        default=[],
        metavar="PATH",
        help="extra checkpoints or folders (before models/folds and the shipped ones)",
    )
    p.add_argument("--seed", type=int, default=None, help="simulator seed (default 2020)")
    p.add_argument("--quick", action="store_true", help="first seconds of each take only")
    p.add_argument(
        "--pairs",
        metavar="DIR",
        help="instead: the MediaPipe tracker table on rendered pairs (faceclean pairs), "
        "leave one source out, plus the still real face; its section of --markdown is "
        "replaced, the rest of the page kept",
    )
    p.add_argument("--lstm", action="store_true", help="with --pairs: also the paper's LSTM")
    p.add_argument(
        "--families",
        action="store_true",
        help="with --pairs: the appearance table (leave one family and one source out) "
        "instead of the tracker table",
    )
    p.add_argument(
        "--jobs", type=int, default=1, metavar="N", help="with --families: folds in parallel"
    )
    p.add_argument(
        "--shipped",
        metavar="NPZ",
        help="with --families: the model of the 'shipped before' row "
        "(default benchmarks/tracker/mediapipe-before.npz)",
    )


def run(args: argparse.Namespace) -> int:
    from faceclean.evaluation import evaluate
    from faceclean.evaluation import results as results_md
    from faceclean.io.atomic import atomic_write, check_writable, together
    from faceclean.io.paths import verb

    def progress(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    check_writable(args.json, args.markdown)  # now, not after the evaluation
    from faceclean.errors import FacecleanError, seed

    if args.seed is not None:  # the simulator's, checked before any fold
        seed(args.seed, "--seed")
    for out in (args.json, args.markdown):  # a file of the data it reads: refused now
        folder = args.data or args.pairs
        if out and folder and Path(out).is_file() and Path(folder).resolve() in \
                Path(out).resolve().parents:  # fmt: skip
            raise FacecleanError(f"{out} is in {folder}, which this command reads: name "
                                 "another file")  # fmt: skip
    if args.pairs and args.families:
        return _families(args, progress)
    if args.pairs:
        return _pairs(args, progress)
    seed = evaluate.SEED if args.seed is None else args.seed
    results = evaluate.evaluate(
        data=args.data, models=args.models, seed=seed, quick=args.quick, progress=progress
    )
    text = results_md.markdown(results)
    text = _keep_tracker_section(args.markdown, text)
    said = {p: verb(p) for p in (args.json, args.markdown) if p}  # "replaced": said, never
    with together():  # in silence (the markdown keeps the sections it does not write);
        if args.json:  # both written, then both renamed
            atomic_write(args.json, evaluate.dumps(results))
        if args.markdown:
            atomic_write(args.markdown, text)
    # The verdict and the table that decide: the second artefact model at 60 fps.
    for head in ("## Never ship worse", "## degrade 60 fps"):
        section = text.split(head, 1)[-1].split("\n## ", 1)[0]
        print(head.lstrip("# ") + section.rstrip() + "\n")
    for path, done in said.items():
        print(f"{done} {path}")
    return 0


def _keep_tracker_section(path: str | None, text: str) -> str:
    """The page's tracker section (``eval --pairs``) survives a rewrite of the rest."""
    from pathlib import Path

    from faceclean.evaluation import tracker_results

    if not path or not Path(path).is_file():
        return text
    old = Path(path).read_text(encoding="utf-8", errors="replace")
    if tracker_results.BEGIN not in old or tracker_results.END not in old:
        return text
    start = old.index(tracker_results.BEGIN)
    section = old[start : old.index(tracker_results.END) + len(tracker_results.END)]
    return tracker_results.insert(text, section + "\n")


# the MediaPipe map shipped before issue 34 (painted faces only): the continuity row
BEFORE = Path(__file__).resolve().parents[3] / "benchmarks" / "tracker" / "mediapipe-before.npz"


def _families(args: argparse.Namespace, progress) -> int:
    """``eval --pairs DIR --families``: the appearance table (evaluation/family_eval.py)."""
    import json
    from pathlib import Path

    from faceclean import settings, workers
    from faceclean.evaluation import family_eval, tracker_results
    from faceclean.io.atomic import atomic_write, together

    before = Path(args.shipped) if args.shipped else (BEFORE if BEFORE.is_file() else None)
    jobs, _ = workers.count(args.jobs, 64, "folds")
    result = family_eval.evaluate(args.pairs, shipped=before, report=progress, jobs=jobs)
    model = settings.tracker_model()
    if model is not None and model.is_file():  # the still real face, the shipped models
        from faceclean.evaluation import still
        from faceclean.learned.tracker_map import TrackerMap

        take = still.still_take(model, seconds=8)
        rows = {"raw": take}
        for label, path in (("shipped before", before),
                            ("shipped now", settings.MODELS / "mediapipe.npz")):  # fmt: skip
            if path is not None:
                rows[label] = TrackerMap(model=path, names=take.names).clean(take)
        result["still"] = {k: still.measures(v) for k, v in rows.items()}
        for v in result["still"].values():
            v["change_ratio"] = v["change"] / result["still"]["raw"]["change"]
    section = family_eval.markdown(result)
    with together():  # both written, then both renamed
        if args.json:
            atomic_write(args.json, json.dumps(result, indent=1))
        if args.markdown:
            page = Path(args.markdown)
            old = page.read_text(encoding="utf-8") if page.is_file() else ""
            atomic_write(args.markdown, tracker_results.insert(
                old, section, family_eval.BEGIN, family_eval.END))  # fmt: skip
    print(section)
    return 0


def _pairs(args: argparse.Namespace, progress) -> int:
    """``eval --pairs DIR``: the tracker table and the still real face."""
    import json
    from pathlib import Path

    from faceclean import resolve, settings
    from faceclean.evaluation import still, tracker_eval, tracker_results
    from faceclean.filters.one_euro import OneEuro
    from faceclean.io.atomic import atomic_write, together
    from faceclean.learned.tracker_map import TrackerMap

    result = tracker_eval.evaluate(args.pairs, lstm=args.lstm, report=progress)
    if not result["folds"]:  # each fold leaves one source out: one source leaves nothing
        from faceclean.errors import FacecleanError

        raise FacecleanError(f"{args.pairs}: no fold to score (each fold leaves one source "
                             "out of the rest: give pairs of two sources or more)")  # fmt: skip
    model = settings.tracker_model()
    still_rows = None
    if model is not None and model.is_file():
        take = still.still_take(model, seconds=8)
        best = max(result["folds"], key=lambda g: len(result["folds"][g]))
        tuned = result["one_euro"][best]  # {"min_cutoff": Hz, "beta": beta}
        shipped = settings.MODELS / resolve.TRACKER_MODELS["mediapipe"]
        rows = {
            "raw": take,
            "one-euro": OneEuro(names=take.names, **tuned).clean(take),
            "tracker map (ours, shipped)": TrackerMap(model=shipped, names=take.names).clean(take),
            "tracker map (shipped), detail 1": TrackerMap(
                model=shipped, names=take.names, detail=1.0
            ).clean(take),
        }
        still_rows = {k: still.measures(v) for k, v in rows.items()}
        for v in still_rows.values():
            v["change_ratio"] = v["change"] / still_rows["raw"]["change"]
    section = tracker_results.markdown(result, still_rows)
    with together():  # both written, then both renamed
        if args.json:
            atomic_write(args.json, json.dumps({"pairs": result, "still": still_rows}, indent=1))
        if args.markdown:
            page = Path(args.markdown)
            old = page.read_text(encoding="utf-8") if page.is_file() else ""
            atomic_write(args.markdown, tracker_results.insert(old, section))
    print(section)
    return 0
