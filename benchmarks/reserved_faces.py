"""The independent check, run in the house: the two reserved photographs as faces.

scikit-image's ``astronaut`` and matplotlib's Grace Hopper portrait are kept out of every
fit and every choice (``portrait.RESERVED``: ``faceclean pairs`` refuses them). Here each
textures the ICT head as the photo family does (``portrait.Fitter``: identity fitted to
the photograph, skin taken from it), performs, and is tracked by MediaPipe: a look, faces
and identities no fit saw. Nothing here feeds a choice; the numbers are reported only
(docs/RESULTS.md "The reserved photographs").

The jobs are ``faceclean pairs``'s own (``engine.plan``: seed ``--seed``, the three render
settings, webcam timing, turning eyes, a 3 s neutral hold of each face), photo family,
the portraits drawn between the two; of its clips ``--clips`` per real source
(alexdjulin, neurosync: evenly over their takes) and ``--made-up`` each of synthetic and
independent performers, netted as the pairs' are, of seeds no pairs job draws. Pairs are
written under ``--cache`` in the pairs format (a rerun renders only what is missing).

Rows (MSE x raw MediaPipe over its 51 channels, per group as docs/RESULTS.md's families):

    raw        MediaPipe's scores as they come
    one-euro   One Euro tuned on the training pairs (``tracker_eval.tune_one_euro``)
    shipped    the shipped map (src/faceclean/models/mediapipe.npz). It never saw these
               looks or faces, nor the made-up performers; it did see the real sources'
               performances (on other faces)
    held out   the map over rises refitted (``map_rises.fit``, every choice its own) on
               the ``--pairs`` of every other source: the real rows' performances unseen
               too. Made-up rows: fitted without either made-up kind; neutral holds: the
               shipped map

Run (about 25 min rendering and 20 min fitting on 2 cores):

    .venv/bin/python benchmarks/reserved_faces.py --pairs ~/.cache/faceclean/families-net \\
        --json docs/results_reserved.json --markdown docs/RESULTS.md
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from faceclean import settings
from faceclean.neural.map_groups import MADE_UP
from faceclean.synthetic import engine

CACHE = Path.home() / ".cache" / "faceclean" / "reserved"
MODEL = Path("src/faceclean/models/mediapipe.npz")
REAL = ("alexdjulin", "neurosync")
ROWS = ("raw", "one-euro", "shipped", "held out")
BEGIN, END = "<!-- reserved faces: begin -->", "<!-- reserved faces: end -->"


def reserved() -> dict[str, np.ndarray]:
    """name -> RGB (H, W, 3) uint8 of the two reserved photographs, from their packages."""
    import matplotlib.cbook
    from PIL import Image
    from skimage import data

    with Image.open(matplotlib.cbook.get_sample_data("grace_hopper.jpg", asfileobj=False)) as im:
        hopper = np.asarray(im.convert("RGB"))
    return {"astronaut": data.astronaut(), "grace_hopper": hopper}


class Worker(engine.Worker):
    """The pairs engine's worker with the reserved photographs as its portraits (the
    product's loader refuses them; only this report reads them)."""

    def portraits(self) -> dict[str, np.ndarray]:
        if self._portraits is None:
            self._portraits = reserved()
        return self._portraits


def jobs(seed: int, clips: int, made_up: int) -> list[engine.Job]:
    """The plan (module docstring): the kept clips, each with its neutral hold."""
    from faceclean import io

    root = settings.takes_dir()
    if root is None:
        raise SystemExit("no shared takes folder (../shared/data/arkit_takes)")
    takes = [(str(p), p.parent.name, io.load(p).duration) for p in sorted(root.rglob("*.csv"))
             if p.parent.name in REAL]  # fmt: skip
    plan = engine.plan(
        takes, made_up, 10.0, ("studio", "webcam", "window"), (24.0, 30.0, 30.0, 30.0, 60.0),
        seed, families=("photo",), portraits=tuple(reserved()), independent=made_up,
        neutral=3.0, gaze=True,
    )  # fmt: skip
    kept: list[engine.Job] = []
    for group in REAL + MADE_UP:
        runs = [k for k, j in enumerate(plan) if j.group == group]
        want = clips if group in REAL else made_up
        picks = np.unique(np.linspace(0, len(runs) - 1, min(want, len(runs))).round().astype(int))
        for k in (runs[i] for i in picks):
            kept += [plan[k], plan[k + 1]]  # the clip, then its face's neutral hold
    return kept


_WORKER: Worker | None = None


def _init() -> None:
    global _WORKER
    _WORKER = Worker(settings.mesh_file("ict_full.npz"), settings.tracker_model())


def _render(job: engine.Job, out: str) -> str:
    assert _WORKER is not None
    _WORKER.run(job, Path(out))
    return job.name


def render(todo: list[engine.Job], out: Path, n_jobs: int) -> None:
    """Every job not yet in ``out`` rendered and tracked, ``n_jobs`` at a time."""
    from concurrent.futures import as_completed

    from faceclean import workers

    todo = [j for j in todo if not engine.done(j, out)]
    out.mkdir(parents=True, exist_ok=True)
    with workers.Pool(n_jobs, _init) as pool:
        futures = [pool.submit(_render, j, str(out)) for j in todo]
        for k, f in enumerate(as_completed(futures), 1):
            print(f"rendered {k}/{len(todo)}: {f.result()}", file=sys.stderr, flush=True)


def evaluate(cache: Path, training: Path | None, model: Path = MODEL) -> dict:
    """{"kinds": {kind: {row: scores}}, "portraits": {...}, "neutral": {row: worst}, ...};
    no ``training``: the raw and shipped rows only (no refits)."""
    from faceclean.datasets import paired
    from faceclean.evaluation.family_eval import NEUTRAL, at_rest, scores
    from faceclean.evaluation.tracker_eval import outputs, tune_one_euro
    from faceclean.filters.one_euro import OneEuro
    from faceclean.learned.tracker_map import TrackerMap
    from faceclean.neural import map_rises

    tests = paired.load(cache, require_meta=True)
    pool = paired.load(training, require_meta=True) if training else []
    shipped = lambda n: TrackerMap(model=model, names=n)  # noqa: E731
    per: dict[str, list] = {r: [] for r in ROWS}  # row -> [(output, pair)]
    folds = [((g,), (g,)) for g in REAL] + [(MADE_UP, MADE_UP)] if pool else []
    for left_out, groups in folds:
        test = [p for p in tests if p.group in groups]
        train = paired.with_clips([p for p in pool if p.group not in left_out])
        mc, beta = tune_one_euro(train)
        rises = map_rises.fit(train)
        builds = {"raw": lambda n: None,
                  "one-euro": lambda n, c=mc, b=beta: OneEuro(names=n, min_cutoff=c, beta=b),
                  "shipped": shipped,
                  "held out": lambda n, w=rises: TrackerMap(weights=w, names=n)}  # fmt: skip
        for row, build in builds.items():
            per[row] += list(zip(outputs(build, test), test, strict=True))
        print(f"fold without {'+'.join(left_out)}: {len(train)} training pairs, "
              f"{len(test)} test", file=sys.stderr, flush=True)  # fmt: skip
    holds = [p for p in tests if p.group == NEUTRAL]
    rest = holds if pool else tests  # what no fold scored: raw and shipped alone
    for row, build in (("raw", lambda n: None), ("shipped", shipped)):
        per[row] += list(zip(outputs(build, rest), rest, strict=True))
    per = {r: v for r, v in per.items() if v}

    def by(key) -> dict:
        out: dict = {}
        for row, outs in per.items():
            for o, p in outs:
                if p.group != NEUTRAL:
                    out.setdefault(key(p), {}).setdefault(row, []).append((o, p))
        return {k: {r: scores(v) for r, v in rows.items()} for k, rows in sorted(out.items())}

    return {
        "kinds": by(lambda p: "made-up" if p.group in MADE_UP else "real"),
        "portraits": by(lambda p: p.meta["scene"]["portrait"]),
        "settings": by(lambda p: p.meta["scene"]["setting"]),
        "neutral": {r: a for r, v in per.items() if (a := at_rest(v))},
        "pairs": {"test": len(tests), "holds": len(holds), "training": len(pool)},
    }


def markdown(result: dict) -> str:
    """The section of docs/RESULTS.md."""
    from faceclean.evaluation.family_eval import TABLE_GROUPS

    lines = [BEGIN, "", "## The reserved photographs: an independent look, reported only", "",
             "scikit-image's `astronaut` and matplotlib's Grace Hopper portrait, kept out of "
             "every fit and every choice, texture the ICT head as the photo family does and "
             "perform: clips of two shared sources (alexdjulin, neurosync) and made-up "
             "performers of seeds no pairs job draws, in the three render settings, tracked by "
             "MediaPipe (`benchmarks/reserved_faces.py`, which says how each row was fitted). "
             "*shipped* saw the real performances on other faces"
             + ("; *held out* is the map over rises refitted without the row's source"
                if "held out" in next(iter(result["kinds"].values())) else "")
             + ". MSE x raw MediaPipe:", "",
             "| performances | row | MSE x raw | " + " | ".join(TABLE_GROUPS)
             + " | blink closure | jitter (x truth) | lag ms | clips |",
             "|---" * (len(TABLE_GROUPS) + 7) + "|"]  # fmt: skip
    for table in ("kinds", "portraits", "settings"):
        for key, rows in result[table].items():
            raw = rows["raw"]
            for row in ROWS:
                s = rows.get(row)
                if s is None:
                    continue
                groups = " | ".join(
                    f"{s[f'mse_{g}'] / raw[f'mse_{g}']:.2f}" if raw[f"mse_{g}"] > 0 else "-"
                    for g in TABLE_GROUPS
                )
                lines.append(
                    f"| {key} | {row} | {s['mse'] / raw['mse']:.2f} | {groups} | "
                    f"{s['blink_closure']:.2f} | {s['jitter_ratio']:.2f} | {s['lag_ms']:.0f} | "
                    f"{s['pairs']} |"
                )
    lines += ["", "A face at rest (the neutral holds, 3 s each, after the first 0.5 s): the worst "
              "channel's mean |output - 0|: " + "; ".join(
                  f"{row} {v['worst']:.3f} ({v['channel']}, {v['holds']} holds)"
                  for row, v in result["neutral"].items()) + ".", "", END]  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", help="the training pairs (make pairs' folder) for the refitted "
                    "rows; none: the raw and shipped rows alone")  # fmt: skip
    ap.add_argument("--model", default=str(MODEL), help="the shipped row's map")
    ap.add_argument("--cache", default=str(CACHE), help="where the reserved faces' pairs go")
    ap.add_argument("--seed", type=int, default=7, help="the plan's seed (not the pairs' 0)")
    ap.add_argument("--clips", type=int, default=9, help="10 s clips per real source")
    ap.add_argument("--made-up", type=int, default=6, help="performers of each made-up kind")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--json", help="write the result here")
    ap.add_argument("--markdown", help="splice the section into this page")
    args = ap.parse_args()
    if args.seed == 0:
        raise SystemExit("--seed 0 is the training pairs' own plan")
    cache = Path(args.cache)
    render(jobs(args.seed, args.clips, args.made_up), cache, args.jobs)
    if args.render_only:
        return 0
    result = evaluate(cache, Path(args.pairs) if args.pairs else None, Path(args.model))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    section = markdown(result)
    if args.markdown:
        from faceclean.evaluation.tracker_results import insert

        page = Path(args.markdown)
        page.write_text(insert(page.read_text(), section, BEGIN, END))
    print(section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
