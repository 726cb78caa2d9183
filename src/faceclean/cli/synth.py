"""``faceclean synth -o OUT --seconds S --seed S``: write a synthetic performance."""

from __future__ import annotations

import argparse

HELP = "write a synthetic ARKit-52 performance (blinks, gaze, speech, expressions)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", metavar="OUT", required=True, help="file to write")
    p.add_argument("--seconds", type=float, default=60.0, help="length in s (default 60)")
    p.add_argument("--seed", type=int, default=0, help="same seed, same performance")
    p.add_argument("--fps", type=float, default=60.0, help="frame rate in Hz (default 60)")
    p.add_argument("--format", dest="fmt", help="output format (csv, livelink, json, npz, gltf)")


def run(args: argparse.Namespace) -> int:
    from faceclean import io
    from faceclean.datasets import performer

    anim = performer.perform(args.seconds, args.seed, args.fps)
    done = io.paths.verb(args.output)
    io.save(anim, args.output, fmt=args.fmt)
    print(f"{done} {args.output}: {anim.n_frames} frames, {anim.duration:.1f} s at {args.fps:g} Hz")
    return 0
