"""``faceclean corrupt IN -o OUT --seed S``: degrade a clean take like a tracker would."""

from __future__ import annotations

import argparse

HELP = "add realistic tracker artefacts to a clean take (seeded, for training and tests)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="IN", help="clean animation file")
    p.add_argument("-o", "--output", metavar="OUT", required=True, help="noisy take to write")
    p.add_argument("--seed", type=int, required=True, help="same seed, byte-identical output")
    p.add_argument(
        "--preset", default="iphone", help="tracker type: iphone, webcam, mixed or clean"
    )
    p.add_argument("--strength", type=float, default=1.0, help="artefact scale (default 1)")
    p.add_argument("--truth-out", metavar="FILE", help="also write the truth at OUT's times")
    p.add_argument("--format", dest="fmt", help="output format (livelink, csv, json, npz, gltf)")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from faceclean import io
    from faceclean.datasets import simulate
    from faceclean.io.atomic import together
    from faceclean.timing import refuse_restarts

    io.paths.distinct(args.output, args.truth_out)
    clean = io.load(args.input)
    refuse_restarts(clean, Path(args.input).name)  # as clean refuses them
    for out in filter(None, (args.output, args.truth_out)):  # both, before writing one
        io.check_output(out, args.fmt, clean.meta.get("format"))
    noisy, truth = simulate.corrupt(clean, args.seed, args.preset, args.strength)
    done = [io.paths.verb(out) for out in (args.output, args.truth_out) if out]
    with together():  # both written, then both renamed: never one new beside one old
        io.save(noisy, args.output, fmt=args.fmt)
        if args.truth_out:
            io.save(truth, args.truth_out, fmt=args.fmt)
    lost = int((~noisy.valid).sum())
    print(
        f"{done[0]} {args.output}: {noisy.n_frames} frames at {noisy.rate:.1f} Hz "
        f"({args.preset}, strength {args.strength:g}, {lost} tracking-loss frames)"
        + (f"; {done[1]} {args.truth_out}: the truth at its times" if args.truth_out else "")
    )
    return 0
