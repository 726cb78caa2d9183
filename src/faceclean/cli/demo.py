"""``faceclean demo``: what faceclean does, on two takes the project made itself.

1. An iPhone-like take: a synthetic performance (faceclean.datasets.performer) degraded
   the way an iPhone tracker degrades it (faceclean.datasets.simulate), written as a Live
   Link Face CSV and cleaned with the shipped default, beside the raw input and the tuned
   One Euro filter. The default *is* that filter today (docs/MODEL.md), so their rows match.
2. A MediaPipe pair shipped in faceclean/data/demo (its README says how ``faceclean pairs``
   made it): a rendered face tracked by MediaPipe, cleaned with the cleaner
   ``--tracker mediapipe`` names, beside raw MediaPipe and the tuned One Euro filter.

Both are scored against their truth (faceclean.evaluation.metrics), in total and per
channel group; every column is explained under the tables (``LEGEND``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from faceclean.settings import PACKAGE

if TYPE_CHECKING:
    from faceclean.animation import Animation
    from faceclean.evaluation.comparison import Comparison

HELP = "clean an iPhone-like take and a MediaPipe pair; print what each cleaner does"
PAIR = PACKAGE / "data" / "demo"  # the shipped MediaPipe pair (tracked, truth, json)
CURVES = ("eyeBlinkLeft", "jawOpen", "mouthSmileLeft")  # channels drawn in curves.png
IPHONE_SPAN = 10.0  # s of the iPhone take drawn (the pair is drawn whole)
ONE_EURO = "one-euro"  # the shipped tuned One Euro preset
LABEL = 20  # characters of a row's label
LEGEND = (
    "columns (both tables; each row scored against the truth, on the channels both carry):",
    "  MSE x raw    mean squared error over channels and frames over the raw input's (< 1: closer)",
    "  gaze..cheeks_nose  that ratio per channel group (gaze: eyeLook*; lids: the other eye ones)",
    "  blink        blink closure: output peak over true peak per true blink, mean (1: as deep)",
    "  jitter       mean squared 2nd time-derivative, output over truth (1: as smooth as the face)",
    "  lag ms       the delay that best aligns the output with the truth, in ms (+: late)",
)

IPHONE = """\
(a) iPhone-like take: a synthetic performance, {seconds:.1f} s at 60 fps, degraded as an iPhone
    tracker degrades it (jitter, shallow blinks, crosstalk, drift, dropped frames), cleaned
    with the shipped default. That default IS the tuned One Euro filter today: the learned
    cleaner, trained on every real source, did not beat it on held-out takes (docs/MODEL.md),
    so the default and one-euro rows match. On an iPhone take faceclean adds that tuned
    filter and the tools around it, not a better model. A group above 1.00 is one where the
    filter's lag costs more than the jitter it takes off: it was tuned on real takes, and
    this made-up performer's jaw moves faster than theirs.
    files in {out}/: noisy.csv (Live Link Face), cleaned.csv, truth.csv,
    curves.png (the first {span:g} s of eyeBlinkLeft, jawOpen, mouthSmileLeft)"""
MEDIAPIPE = """\
(b) MediaPipe pair: a rendered face (look family groomed, studio setting) tracked by
    MediaPipe Face Landmarker, {seconds:.1f} s at {fps:g} fps, {channels} channels, shipped in the
    package (faceclean/data/demo/README.md says how it was made). Cleaned with --tracker
    mediapipe (models/mediapipe.npz: a map over each channel's rise above rest), beside raw
    MediaPipe and the tuned One Euro filter. That cleaner never saw this performer
    (synthetic seed {performer}), this face nor its look: eyeliner, eyeshadow, a beard and
    freckles, a family no shipped fit trains on (held-out figures: docs/RESULTS.md,
    "MediaPipe on looks no fit saw").
    files in {out}/: tracked.csv (raw), cleaned.csv, one-euro.csv, truth.csv,
    curves.png (eyeBlinkLeft, jawOpen, mouthSmileLeft)"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/demo", help="folder for the files (default: out/demo)")
    p.add_argument("--seconds", type=float, default=30.0, help="length of the iPhone-like take (s)")
    p.add_argument("--seed", type=int, default=7, help="seed of the iPhone-like take")


def run(args: argparse.Namespace) -> int:
    from faceclean.errors import FacecleanError

    out = Path(args.out)
    if args.seconds <= 0:
        raise FacecleanError("--seconds must be positive")
    out.mkdir(parents=True, exist_ok=True)
    print("faceclean demo: two takes the project made itself, each cleaned, then scored")
    print("against the performance that made it (its truth).\n")
    iphone(out / "iphone", args.seconds, args.seed)
    print()
    mediapipe(out / "mediapipe")
    print()
    print("\n".join(LEGEND))
    return 0


def iphone(out: Path, seconds: float, seed: int) -> None:
    """Table (a): the iPhone-like take, raw / the shipped default / the tuned One Euro."""
    from faceclean import io
    from faceclean.datasets import performer, simulate
    from faceclean.evaluation import comparison
    from faceclean.resolve import DEFAULT

    out.mkdir(parents=True, exist_ok=True)
    clean = performer.perform(seconds, seed=seed, fps=60.0)
    noisy, truth = simulate.corrupt(clean, seed=seed + 1, preset="iphone")
    io.save(noisy, out / "noisy.csv", fmt="livelink")
    io.save(truth, out / "truth.csv", fmt="csv")
    take = io.load(out / "noisy.csv")  # the main job starts from the file, as a user's would
    comp = comparison.compare(take, truth, [DEFAULT, ONE_EURO])
    cleaned = comp.outputs[DEFAULT]
    io.save(cleaned, out / "cleaned.csv")  # a Live Link Face CSV again
    # one cleaned curve: the default and the tuned One Euro would lie on top of each other
    shown = comparison.Comparison(take, comp.truth, {"default (= tuned one-euro)": cleaned})
    _figure(shown, out / "curves.png", IPHONE_SPAN)

    print(IPHONE.format(out=out, seconds=take.duration, span=IPHONE_SPAN))
    rows = {"raw input": take, "default": cleaned, "one-euro (tuned)": comp.outputs[ONE_EURO]}
    _table(rows, truth)


def mediapipe(out: Path) -> None:
    """Table (b): the shipped MediaPipe pair, raw / ``--tracker mediapipe`` / tuned One Euro."""
    from faceclean import io
    from faceclean.datasets import paired
    from faceclean.evaluation import comparison
    from faceclean.resolve import resolve, tracker_words

    out.mkdir(parents=True, exist_ok=True)
    [pair] = paired.load(PAIR)
    job = pair.meta.get("job", {})
    raw, truth = pair.tracked, pair.truth  # truth: ARKit-52 at the tracked instants
    methods = [("--tracker mediapipe", resolve(tracker_words("mediapipe"))),
               ("one-euro (tuned)", resolve(ONE_EURO))]  # fmt: skip
    comp = comparison.compare(raw, truth, methods)
    io.save(raw, out / "tracked.csv", fmt="csv")
    io.save(truth, out / "truth.csv", fmt="csv")
    io.save(comp.outputs["--tracker mediapipe"], out / "cleaned.csv", fmt="csv")
    io.save(comp.outputs["one-euro (tuned)"], out / "one-euro.csv", fmt="csv")
    _figure(comp, out / "curves.png", None)

    performer = str(job.get("source", "?")).split(":")[-1]  # "synth:700000"
    print(MEDIAPIPE.format(out=out, seconds=raw.duration, fps=job.get("rate", 0),
                           channels=len(raw.names), performer=performer))  # fmt: skip
    rows = {"raw MediaPipe": raw, **comp.outputs}
    _table(rows, truth)


def scores(anim: Animation, truth: Animation) -> dict[str, float]:
    """metrics.summary (mse, jitter_ratio, lag_ms, blink_closure) and the MSE of each
    group of family_eval.TABLE_GROUPS (the groups of docs/RESULTS.md's MediaPipe tables)."""
    from faceclean.evaluation import metrics
    from faceclean.evaluation.family_eval import TABLE_GROUPS

    res = metrics.summary(anim, truth)
    p, y, names = metrics.paired(anim, truth)
    for group, members in TABLE_GROUPS.items():
        cols = [j for j, n in enumerate(names) if n in members]
        res[group] = metrics.mse(p[:, cols], y[:, cols]) if cols else float("nan")
    return res


def _table(rows: dict[str, Animation], truth: Animation) -> None:
    """One table: the first row is the raw input, every MSE a ratio to its own."""
    from faceclean.evaluation.family_eval import TABLE_GROUPS

    got = {label: scores(anim, truth) for label, anim in rows.items()}
    raw = next(iter(got.values()))
    groups = list(TABLE_GROUPS)
    print(f"    raw input's MSE: {raw['mse']:.4g} (the 1.00 of the table)")
    head = f"{'':{LABEL}}{'MSE x raw':>10}" + "".join(f"{g:>{_width(g)}}" for g in groups)
    print(head + f"{'blink':>7}{'jitter':>8}{'lag ms':>8}")
    for label, s in got.items():
        cells = [f"{_ratio(s['mse'], raw['mse']):>10.2f}"]
        cells += [f"{_ratio(s[g], raw[g]):>{_width(g)}.2f}" for g in groups]
        cells += [f"{s['blink_closure']:>7.2f}", f"{s['jitter_ratio']:>8.3g}",
                  f"{s['lag_ms']:>8.0f}"]  # fmt: skip
        print(f"{label:{LABEL}}" + "".join(cells))


def _width(group: str) -> int:
    return max(6, len(group) + 1)


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else float("nan")


def _figure(comp: Comparison, path: Path, span: float | None) -> None:
    """Truth, input and each output on CURVES, over the first ``span`` s (None: all)."""
    from faceclean.report import plot

    end = None if span is None else min(span, float(comp.times[-1]))
    plot.save_figure(comp, path, list(CURVES), 0.0, end)
