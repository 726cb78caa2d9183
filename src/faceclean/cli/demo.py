"""``faceclean demo``: the main job end to end on an example clip the project makes itself.

A synthetic performance (faceclean.evaluation.performer) is degraded the way an iPhone tracker
degrades it (faceclean.evaluation.simulate), written as a Live Link Face CSV, cleaned with the
shipped default cleaner, and measured against the clean performance.
"""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "clean an example noisy capture with the shipped default cleaner"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/demo", help="folder for the files (default: out/demo)")
    p.add_argument("--seconds", type=float, default=30.0, help="length of the example clip (s)")
    p.add_argument("--seed", type=int, default=7, help="seed of the example clip")


def run(args: argparse.Namespace) -> int:
    from faceclean import io
    from faceclean.errors import FacecleanError
    from faceclean.evaluation import comparison, metrics, performer, simulate
    from faceclean.report import plot
    from faceclean.resolve import DEFAULT, resolve

    out = Path(args.out)
    if args.seconds <= 0:
        raise FacecleanError("--seconds must be positive")
    out.mkdir(parents=True, exist_ok=True)
    clean = performer.perform(args.seconds, seed=args.seed, fps=60.0)
    noisy, truth = simulate.corrupt(clean, seed=args.seed + 1, preset="iphone")
    noisy_path, truth_path, cleaned_path = out / "noisy.csv", out / "truth.csv", out / "cleaned.csv"
    io.save(noisy, noisy_path, fmt="livelink")
    io.save(truth, truth_path, fmt="csv")

    method = DEFAULT
    take = io.load(noisy_path)  # the main job starts from the file, as a user's would
    cleaned = resolve(method).build(take.names).clean(take)
    io.save(cleaned, cleaned_path)

    # The same clip through the tuned One Euro filter, the usual tool, for comparison.
    comp = comparison.compare(take, truth, [method, "one-euro"])
    figure_path = out / "curves.png"
    plot.save_figure(comp, figure_path, ["eyeBlinkLeft", "jawOpen", "mouthSmileLeft"], 0.0, 10.0)

    rows = {"raw input": take, method: cleaned, "one-euro (tuned)": comp.outputs["one-euro"]}
    print(f"example clip: {noisy.n_frames} frames, {noisy.duration:.1f} s -> {noisy_path}")
    print(f"cleaned with {method!r} -> {cleaned_path}  (truth: {truth_path})")
    print(f"curves (first 10 s) -> {figure_path}")
    keys = ("mse", "jitter_ratio", "lag_ms", "blink_closure")
    print(f"{'':18}" + "".join(f"{k:>14}" for k in keys))
    for label, anim in rows.items():
        m = metrics.summary(anim, truth)
        print(f"{label:18}" + "".join(f"{m[k]:14.4g}" for k in keys))
    return 0
