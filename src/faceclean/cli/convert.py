"""``faceclean convert IN -o OUT``: change an animation's file format, values untouched."""

from __future__ import annotations

import argparse

HELP = "convert between Live Link CSV, CSV, JSON, NPZ and glTF/GLB"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="IN", help="animation file to read")
    p.add_argument("-o", "--output", metavar="OUT", required=True, help="where to write")
    p.add_argument("--format", dest="fmt", help="output format (livelink, csv, json, npz, gltf)")


def run(args: argparse.Namespace) -> int:
    from faceclean import io

    anim = io.load(args.input)
    io.save(anim, args.output, fmt=args.fmt)
    print(
        f"wrote {args.output}: {anim.n_frames} frames, {anim.n_channels} channels "
        f"({anim.meta.get('format')} -> {args.fmt or io.detect(args.output)})"
    )
    return 0
