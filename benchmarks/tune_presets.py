"""Regenerate the shipped presets src/faceclean/presets/{ema,one-euro,kalman}.json.

Each cleaner is tuned per channel group (faceclean.filters.tune, MSE objective) on
simulator-corrupted real takes: every take of the ``neurosync`` and ``alexdjulin``
sources in ../shared/data/arkit_takes (the ``jmtechart`` clip stays out), corrupted
with ``simulate.corrupt(take, seed, preset)`` for SEEDS seeds each. The default
simulator preset is "mixed" (iPhone and webcam artefacts, 24-120 fps, irregular timing),
so the shipped presets are one compromise for every rate; pass --sim iphone or webcam
to tune for one tracker.

    .venv/bin/python benchmarks/tune_presets.py [--sim mixed] [--seeds 2] [--out DIR]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from faceclean.datasets.dataset import load_takes
from faceclean.datasets.simulate import corrupt
from faceclean.filters import tune
from faceclean.settings import PRESETS

SOURCES = ("neurosync", "alexdjulin")
METHODS = ("ema", "one-euro", "kalman")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim", default="mixed", help="simulator preset (iphone, webcam, mixed)")
    ap.add_argument("--seeds", type=int, default=2, help="corrupted copies per take")
    ap.add_argument("--out", type=Path, default=PRESETS, help="folder for the preset files")
    ap.add_argument("--methods", nargs="+", default=list(METHODS))
    args = ap.parse_args()

    takes = [t for t in load_takes() if t.source in SOURCES]
    pairs = [
        corrupt(t.animation, seed=1000 * s + i, preset=args.sim)
        for s in range(args.seeds)
        for i, t in enumerate(takes)
    ]
    frames = sum(n.n_frames for n, _ in pairs)
    print(f"{len(takes)} takes from {', '.join(SOURCES)}; {len(pairs)} pairs, {frames} frames")
    args.out.mkdir(parents=True, exist_ok=True)
    for method in args.methods:
        t0 = time.perf_counter()
        result = tune.tune(method, pairs, per_group=True)
        about = {
            "tuned_on": f"{len(takes)} takes of {', '.join(SOURCES)} (../shared/data/arkit_takes)",
            "simulator": f"simulate.corrupt(preset={args.sim!r}), {args.seeds} seeds per take",
            "frames": frames,
            "script": "benchmarks/tune_presets.py",
        }
        path = args.out / f"{method}.json"
        result.save(path, about=about)
        print(f"{method}: {time.perf_counter() - t0:.1f} s -> {path}")
        for unit in result.mse:
            values = result.groups.get(unit, result.params)
            text = ", ".join(f"{k}={v:g}" for k, v in values.items())
            print(
                f"  {unit:<12} raw {result.raw_mse[unit]:.3g}  tuned {result.mse[unit]:.3g}  {text}"
            )


if __name__ == "__main__":
    main()
