"""``faceclean tune NOISY --truth CLEAN --method one-euro -o preset.json``.

Searches a classical cleaner's parameters so that cleaning NOISY comes closest (MSE) to
CLEAN, globally or per channel group, and saves a preset that ``clean --preset`` loads.
Several NOISY/CLEAN pairs may be given, in the same order. The files may be in any
readable format and at different instants: CLEAN is interpolated at NOISY's times.

``--method rotation`` tunes the head and eye angles' filter instead, on the takes' angles
(Live Link's 9, or a plain CSV's angle columns; per group: head, eyes), the angles of a
tracking-loss frame missing as ``clean`` treats them; its preset goes to ``clean
--preset`` beside the blendshapes' own ``--method``/``--model``.
"""

from __future__ import annotations

import argparse
import sys

HELP = "tune a classical cleaner against ground truth and save a preset"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("noisy", metavar="NOISY", nargs="+", help="noisy animation file(s)")
    p.add_argument(
        "--truth", metavar="CLEAN", nargs="+", required=True, help="clean file(s), same order"
    )
    p.add_argument(
        "--method",
        default="one-euro",
        help="ema, one-euro, kalman, gaussian, savgol; rotation: the head and eye angles",
    )
    p.add_argument("--per-group", action="store_true", help="tune each channel group apart")
    p.add_argument("-o", "--output", metavar="PRESET", required=True, help="preset JSON to write")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from tqdm import tqdm

    from faceclean import io
    from faceclean.errors import FacecleanError
    from faceclean.filters import tune
    from faceclean.timing import refuse_restarts

    if len(args.noisy) != len(args.truth):
        raise FacecleanError(
            f"{len(args.noisy)} NOISY file(s) but {len(args.truth)} --truth file(s)"
        )
    if Path(args.output).suffix.lower() != ".json":
        raise FacecleanError(f"{args.output}: a preset is a .json file")
    pairs = []
    for n, c in zip(args.noisy, args.truth, strict=True):
        noisy, truth = io.load(n), io.load(c)
        for anim, name in ((noisy, n), (truth, c)):  # as clean refuses them
            refuse_restarts(anim, Path(name).name)
        if args.method == "rotation":  # the head and eye angles, not the blendshapes
            noisy, truth = angles(noisy, n), angles(truth, c)
        pairs.append((noisy, tune.align(noisy, truth)))
    io.check_output(args.output, "json")  # refused now (e.g. it names the truth), not after
    bar = tqdm(
        total=1 + tune.REFINE, desc="tuning", unit="pass", file=sys.stderr, leave=False, delay=1.0
    )  # delay: a refusal in the first second prints no bar

    def progress(done: int, total: int) -> None:
        bar.update(done - bar.n)

    try:
        result = tune.tune(args.method, pairs, per_group=args.per_group, progress=progress)
    finally:
        bar.close()
    about = {
        "noisy": [Path(n).name for n in args.noisy],
        "truth": [Path(c).name for c in args.truth],
    }
    done = io.paths.verb(args.output)
    result.save(args.output, about=about)
    print(f"{'unit':<12} {'raw MSE':>10} {'tuned MSE':>10}  parameters")
    for unit in result.mse:
        values = result.groups.get(unit, result.params)
        text = ", ".join(f"{k}={v:g}" for k, v in values.items())
        print(f"{unit:<12} {result.raw_mse[unit]:>10.3g} {result.mse[unit]:>10.3g}  {text}")
    print(f"{done} {args.output} ({args.method}{', per group' if args.per_group else ''})")
    return 0


def angles(anim, label: str):
    """The take's head/eye angles (rad) as an animation of their own; a tracking-loss
    frame's angles missing (as ``clean`` steps them)."""
    import numpy as np

    from faceclean.animation import Animation
    from faceclean.errors import FacecleanError
    from faceclean.filters.rotation import pose_columns

    cols, names = pose_columns(anim)
    if not cols:
        raise FacecleanError(
            f"{label}: no head or eye angles (HeadYaw, LeftEyePitch, ...) to tune the rotation "
            "filter on"
        )
    a = np.array(anim.meta["pose"], dtype=np.float64)[:, cols]
    a[~anim.valid] = np.nan
    return Animation(anim.times, a, names)
