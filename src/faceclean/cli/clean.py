"""``faceclean clean IN -o OUT``: clean a file with one cleaner and write it back.

The output format follows OUT's extension (``--format`` forces one); a ``.csv`` out of a
Live Link Face CSV stays Live Link, with only the blendshape values changed. OUT may be
IN: the input is read whole and the output replaces it atomically.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from faceclean.animation import Animation
    from faceclean.filters.base import Cleaner

HELP = "clean an animation file (Live Link CSV, CSV, JSON, NPZ, glTF/GLB)"
PROGRESS_FRAMES = 5000  # show a progress bar from this many frames on


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="IN", help="animation file to clean")
    p.add_argument("-o", "--output", metavar="OUT", required=True, help="where to write")
    p.add_argument("--method", help="cleaner (default: the shipped default cleaner)")
    p.add_argument(
        "--set",
        dest="params",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        help="cleaner parameter, repeatable (numbers, true/false, JSON lists, strings)",
    )
    p.add_argument(
        "--preset",
        metavar="FILE",
        help="preset file made by 'faceclean tune', or a shipped preset's name (--set overrides)",
    )
    p.add_argument("--format", dest="fmt", help="output format (livelink, csv, json, npz, gltf)")


def parse_params(items: list[str]) -> dict[str, Any]:
    """``["min_cutoff=1.5", "fast=true"]`` -> ``{"min_cutoff": 1.5, "fast": True}``."""
    from faceclean.errors import FacecleanError

    params: dict[str, Any] = {}
    for item in items:
        key, eq, text = item.partition("=")
        key = key.strip().replace("-", "_")
        if not eq or not key:
            raise FacecleanError(f"--set {item!r}: expected KEY=VALUE")
        low = text.strip().lower()
        if low in ("true", "yes", "on"):
            params[key] = True
        elif low in ("false", "no", "off"):
            params[key] = False
        else:
            try:
                params[key] = json.loads(text)
            except json.JSONDecodeError:
                params[key] = text
    return params


def run(args: argparse.Namespace) -> int:
    from faceclean import filters, io
    from faceclean.errors import FacecleanError

    anim = io.load(args.input)
    params = parse_params(args.params)
    if args.preset is not None:
        if args.method:
            raise FacecleanError("--preset names its method: give --preset or --method, not both")
        from faceclean.filters import presets

        cleaner = presets.build(args.preset, anim.names, overrides=params or None)
        what = f"{cleaner.name} (preset {args.preset})"
    else:
        method = args.method or filters.default_method()
        cleaner = filters.make(method, params, names=anim.names)
        what = method
    what += f" {json.dumps(params)}" if params else ""
    cleaned = clean_with_progress(cleaner, anim)
    io.save(cleaned, args.output, fmt=args.fmt)
    missing = int((~anim.valid).sum())
    print(
        f"wrote {args.output}: {anim.n_frames} frames"
        + (f" ({missing} missing)" if missing else "")
        + f", {anim.n_channels} channels, cleaned with {what}"
    )
    return 0


def clean_with_progress(cleaner: Cleaner, anim: Animation) -> Animation:
    """``cleaner.clean(anim)``, with a progress bar on stderr for long stream cleans.

    A stream cleaner that keeps the base batch path is stepped here frame by frame, which
    is the same computation (reset, then step every valid frame).
    """
    import numpy as np
    from tqdm import tqdm

    from faceclean.filters.base import Cleaner

    valid = np.flatnonzero(anim.valid)
    if cleaner.offline or type(cleaner).clean is not Cleaner.clean or len(valid) < PROGRESS_FRAMES:
        return cleaner.clean(anim)
    cleaner.reset()
    out = np.full_like(anim.values, np.nan)
    for i in tqdm(valid, unit="frame", file=sys.stderr, leave=False, desc="cleaning"):
        out[i] = cleaner.step(anim.values[i], anim.times[i])
    return anim.with_values(out)
