"""``faceclean clean IN -o OUT``: clean a file with one cleaner and write it back.

Batch: ``faceclean clean A.csv B.csv -o OUTDIR/`` or ``faceclean clean FOLDER -o OUTDIR/``
(recursing; each file keeps its relative path and its format) with one progress bar, a
line per file and a summary of what failed and why; exit 1 when any file failed (the
others are written, a failed one leaves nothing). ``--jobs N`` cleans N files at once.

Levels (before the cleaner, faceclean.adjust): ``--calibration calib.json`` (from
``faceclean calibrate``) and ``--set PATTERN.KEY=VALUE`` with KEY gain, offset, curve,
clamp or off, on a channel name, a glob or a group: ``--set 'eyeBlink*.gain=1.2'
--set tongueOut.off --set jawOpen.clamp=0,0.8``.

The output format follows OUT's extension (``--format`` forces one); a ``.csv`` out of a
Live Link Face CSV stays Live Link, with only the blendshape values changed. OUT may be
IN: the output replaces it atomically once complete. A causal cleaner on a Live Link or
plain CSV written to the same format streams the file in blocks (constant memory,
faceclean.io.stream); anything else is read whole.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pathlib import Path

    from faceclean.animation import Animation
    from faceclean.filters.base import Cleaner

HELP = "clean an animation file (Live Link CSV, CSV, JSON, NPZ, glTF/GLB)"
EPILOG = """\
batch cleaning:
  faceclean clean a.csv b.csv -o OUTDIR/      several files into a folder
  faceclean clean takes/ -o cleaned/ --jobs 2  a folder, recursing: same relative paths and
                                              formats; a line per file, a summary of what
                                              failed and why, exit 1 if any file failed
per-channel levels (before the cleaner; y = clip(sign(u)|u|^curve, lo, hi),
u = gain (x - offset); by channel name, glob or group):
  --set 'eyeBlink*.gain=1.2' --set tongueOut.off --set jawOpen.clamp=0,0.8
  --calibration calib.json                    from 'faceclean calibrate' (--set goes on top)
"""
PROGRESS_FRAMES = 5000  # show a progress bar from this many frames on
PROGRESS_BYTES = 8 << 20  # ... or, when streaming a file, from this many bytes on


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="IN", nargs="+", help="animation file(s) or folder(s)")
    p.add_argument(
        "-o",
        "--output",
        metavar="OUT",
        required=True,
        help="where to write; a folder (OUTDIR/) for several inputs or a folder input",
    )
    p.add_argument("--method", help="cleaner (default: the shipped default cleaner)")
    p.add_argument(
        "--set",
        dest="params",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        help="cleaner parameter, repeatable (numbers, true/false, JSON lists, strings); "
        "PATTERN.gain|offset|curve|clamp|off=VALUE maps a channel's level before cleaning "
        "(e.g. 'eyeBlink*.gain=1.2', tongueOut.off)",
    )
    p.add_argument(
        "--preset",
        metavar="FILE",
        help="preset file made by 'faceclean tune', or a shipped preset's name (--set overrides)",
    )
    p.add_argument(
        "--model",
        metavar="FILE",
        help="a learned model: .npz (e.g. fine-tuned by 'faceclean train --resume default') "
        "or .onnx (made by 'faceclean export')",
    )
    p.add_argument("--format", dest="fmt", help="output format (livelink, csv, json, npz, gltf)")
    p.add_argument(
        "--calibration",
        metavar="FILE",
        help="level mapping from 'faceclean calibrate', applied before the cleaner",
    )
    p.add_argument(
        "--jobs", type=int, default=1, metavar="N", help="batch: clean N files at once (processes)"
    )


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
    from faceclean.cli import clean_batch
    from faceclean.errors import FacecleanError

    if clean_batch.is_batch(args.input, args.output):
        return clean_batch.run(args)
    if args.jobs != 1:
        raise FacecleanError("--jobs is for a batch (several files, or a folder)")
    print(clean_one(args, args.input[0], args.output))
    return 0


def clean_one(args: argparse.Namespace, input: str, output: str, progress: bool = True) -> str:
    """Clean one file as the options ask; the line that says what was written."""
    from pathlib import Path

    from faceclean import io
    from faceclean.adjust import Adjusted, split_items
    from faceclean.io import stream

    levels, rest = split_items(args.params)
    params = parse_params(rest)
    src = Path(input)
    fmt_in = io.detect(src) if src.is_file() else None
    if fmt_in in stream.FORMATS and io.output_format(output, fmt_in, args.fmt) == fmt_in:
        names = stream.channel_names(src, fmt_in)
        cleaner, what = build_cleaner(args, params, names)
        if names and stream.can_stream(cleaner, fmt_in, fmt_in):
            adjust = build_levels(args, levels, names)
            if not adjust.is_identity:
                cleaner = Adjusted(cleaner, adjust, names)
            frames, missing = _stream(src, output, cleaner, fmt_in, progress)
            return _line(output, frames, missing, names, what, adjust)
    anim = io.load(src)
    cleaner, what = build_cleaner(args, params, anim.names)
    adjust = build_levels(args, levels, anim.names)
    mapped = anim.with_values(adjust.apply(anim.values, anim.names))
    cleaned = clean_with_progress(cleaner, mapped) if progress else cleaner.clean(mapped)
    io.save(cleaned, output, fmt=args.fmt)
    return _line(output, anim.n_frames, int((~anim.valid).sum()), anim.names, what, adjust)


def build_levels(args: argparse.Namespace, items: list, names: tuple[str, ...]):
    """The level mapping: ``--calibration``, then the ``--set`` level items on top."""
    from faceclean.adjust import Adjust

    base = Adjust.load(args.calibration) if getattr(args, "calibration", None) else Adjust()
    return base.merged(Adjust.from_overrides(items, names))


def build_cleaner(
    args: argparse.Namespace, params: dict[str, Any], names: tuple[str, ...]
) -> tuple[Cleaner, str]:
    """The cleaner ``--method``/``--preset``/``--set`` ask for, and how to name it."""
    from faceclean import filters
    from faceclean.errors import FacecleanError

    if getattr(args, "model", None):
        if args.method or args.preset is not None or params:
            raise FacecleanError("--model is the cleaner: give it without --method/--preset/--set")
        from faceclean.cleaner import build

        return build(args.model, names)
    if args.preset is not None:
        if args.method:
            raise FacecleanError("--preset names its method: give --preset or --method, not both")
        from faceclean.filters import presets

        cleaner = presets.build(args.preset, names, overrides=params or None)
        what = f"{cleaner.name} (preset {args.preset})"
    else:
        method = args.method or filters.default_method()
        cleaner = filters.make(method, params, names=names)
        what = method
    return cleaner, what + (f" {json.dumps(params)}" if params else "")


def _line(out: str, frames: int, missing: int, names: tuple[str, ...], what: str, adjust) -> str:
    n = 0 if adjust.is_identity else len(adjust.levels(names).active)
    return (
        f"wrote {out}: {frames} frames"
        + (f" ({missing} missing)" if missing else "")
        + f", {len(names)} channels, cleaned with {what}"
        + (f" after levels on {n} channels" if n else "")
    )


def _stream(
    src: Path, out: str, cleaner: Cleaner, fmt: str, progress: bool = True
) -> tuple[int, int]:
    """``stream.clean_file`` with a progress bar (bytes) on stderr for big files."""
    from tqdm import tqdm

    from faceclean.io import stream

    size = src.stat().st_size
    if size < PROGRESS_BYTES or not progress:
        return stream.clean_file(src, out, cleaner, fmt)
    with tqdm(total=size, unit="B", unit_scale=True, file=sys.stderr, leave=False) as bar:
        return stream.clean_file(src, out, cleaner, fmt, progress=bar.update)


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
