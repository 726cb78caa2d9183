"""``faceclean clean IN -o OUT``: clean a file with one cleaner and write it back.

Batch: ``faceclean clean A.csv B.csv -o OUTDIR/`` or ``faceclean clean FOLDER -o OUTDIR/``
(recursing; each file keeps its relative path and its format) with one progress bar, a
line per file and a summary of what failed and why; exit 1 when any file failed (the
others are written, a failed one leaves nothing). ``--jobs N`` cleans N files at once.

The cleaner: ``--method``/``--model``/``--preset`` and ``--set`` (faceclean.resolve;
``--help`` lists the forms). Levels (before the cleaner, faceclean.adjust):
``--calibration calib.json`` (from ``faceclean calibrate``) and ``--set PATTERN.KEY=VALUE``
with KEY gain, offset, curve, clamp or off, on a channel name, a glob or a group:
``--set 'eyeBlink*.gain=1.2' --set tongueOut.off --set jawOpen.clamp=0,0.8``.

The output format follows OUT's extension (``--format`` forces one); a ``.csv`` out of a
Live Link Face CSV stays Live Link, with only the blendshape values changed. Every
output replaces its file atomically once complete. A causal cleaner on a Live Link or
plain CSV written to the same format streams the file in blocks (constant memory,
faceclean.io.stream); anything else is read whole. Head and eye angles (a Live Link
file's 9 angle columns, ``meta["pose"]``) are cleaned by the rotation filter
(filters/rotation.py, its tuned preset; ``--set head.min_cutoff=0.5``, ``eyes.beta=...``).

A raw take is never replaced by accident: an OUT that is IN (``./IN``, a symlink to it,
a hard link of it: the same file, ``os.path.samefile``) is refused unless ``--in-place``
is given, for one file and for a batch into the input folder; ``clean IN --in-place``
(no ``-o``) replaces IN. A folder input needs a folder output, never ``-o name.csv``.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from faceclean.cli import options

if TYPE_CHECKING:
    from pathlib import Path

    from faceclean.animation import Animation
    from faceclean.filters.base import Cleaner
    from faceclean.resolve import Choice

HELP = "clean an animation file (Live Link CSV, CSV, JSON, NPZ, glTF/GLB)"
EPILOG = (
    options.SETTINGS_HELP
    + """\
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
)
PROGRESS_FRAMES = 5000  # show a progress bar from this many frames on
PROGRESS_BYTES = 8 << 20  # ... or, when streaming a file, from this many bytes on


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="IN", nargs="+", help="animation file(s) or folder(s)")
    p.add_argument(
        "-o",
        "--output",
        metavar="OUT",
        help="where to write; a folder (OUTDIR/) for several inputs or a folder input",
    )
    p.add_argument(
        "--in-place",
        action="store_true",
        help="let OUT be IN (or a folder of inputs): replace the raw take(s), atomically",
    )
    options.add_arguments(p)
    p.add_argument("--format", dest="fmt", help="output format (livelink, csv, json, npz, gltf)")
    p.add_argument(
        "--scale",
        type=float,
        metavar="FACTOR",
        help="multiply the blendshape values by FACTOR first (0.01: a take in percent); "
        "without it a take far outside [0, 1] is refused",
    )
    p.add_argument(
        "--jobs", type=int, default=1, metavar="N", help="batch: clean N files at once (processes)"
    )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from faceclean.cli import clean_batch
    from faceclean.errors import FacecleanError

    if args.output is None:
        if not args.in_place:
            raise FacecleanError("give -o OUT (or --in-place to replace the input)")
        if len(args.input) > 1 or Path(args.input[0]).is_dir():
            raise FacecleanError("--in-place without -o is for one file: give -o OUTDIR/")
        args.output = args.input[0]
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
    from faceclean.adjust import Adjusted, check_range
    from faceclean.errors import FacecleanError
    from faceclean.filters import rotation
    from faceclean.io import stream

    choice = options.choice(args)
    src = Path(input)
    if same_file(src, output):
        if not getattr(args, "in_place", False):
            raise FacecleanError(
                f"-o {output} is the input {input}: a raw take is never overwritten; "
                "name another file, or add --in-place to replace it"
            )
        io.paths.rewritable(src)  # --in-place: replaces IN atomically, once complete
    fmt_in = io.detect(src) if src.is_file() else None
    fmt_out = io.output_format(output, fmt_in, args.fmt) if fmt_in in stream.FORMATS else None
    if stream.can_stream(fmt_in, fmt_out):
        names = stream.channel_names(src, fmt_in)
        cleaner, what = build_cleaner(choice, names)
        if names and cleaner.stepwise:
            adjust = build_levels(args, choice, names)
            if not adjust.is_identity:
                cleaner = Adjusted(cleaner, adjust, names)
            guard = None if args.scale is not None else (names, input)
            pose = None
            if angles := stream.angle_names(src, fmt_in):
                pose = choice.build_pose(angles)
            frames, missing = _stream(src, output, cleaner, fmt_in, progress, guard, pose)
            return _line(output, frames, missing, names, what, adjust, choice, pose)
    anim = io.load(src)
    if args.scale is None:  # the same judgement as the stream's, block by block
        for a in range(0, max(anim.n_frames, 1), stream.BLOCK):
            check_range(anim.values[a : a + stream.BLOCK], anim.names, input)
    cleaner, what = build_cleaner(choice, anim.names)
    adjust = build_levels(args, choice, anim.names)
    mapped = anim.with_values(adjust.apply(anim.values, anim.names))
    cleaned = clean_with_progress(cleaner, mapped) if progress else cleaner.clean(mapped)
    cleaned = rotation.clean_pose(cleaned, choice.build_pose)
    io.save(cleaned, output, fmt=args.fmt)
    angles = rotation.pose_columns(anim)[1]
    missing = int((~anim.valid).sum())
    return _line(output, anim.n_frames, missing, anim.names, what, adjust, choice, angles)


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether paths a and b name one existing file (``./``, symlinks, hard links)."""
    import os

    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # either one missing: not the same file
        return False


def build_levels(args: argparse.Namespace, choice: Choice, names: tuple[str, ...]):
    """The level mapping: ``--calibration``, then the ``--set`` level items on top."""
    from faceclean.adjust import Adjust

    base = options.calibration(args) or Adjust()
    levels = base.merged(choice.adjust(names))
    scale = getattr(args, "scale", None)
    return levels if scale is None else levels.scaled(scale)


def build_cleaner(choice: Choice, names: tuple[str, ...]) -> tuple[Cleaner, str]:
    """The cleaner the options chose, for these channels, and how to name it."""
    return choice.build(names), choice.source


def _line(
    out: str,
    frames: int,
    missing: int,
    names: tuple[str, ...],
    what: str,
    adjust,
    choice: Choice,
    angles=None,
) -> str:
    n = 0 if adjust.is_identity else len(adjust.levels(names).active)
    n_angles = len(getattr(angles, "names", angles) or ())
    return (
        f"wrote {out}: {frames} frames"
        + (f" ({missing} missing)" if missing else "")
        + f", {len(names)} channels, cleaned with {what}"
        + (f" after levels on {n} channels" if n else "")
        + (f"; {n_angles} head/eye angles with {choice.pose_source}" if n_angles else "")
    )


def _stream(
    src: Path,
    out: str,
    cleaner: Cleaner,
    fmt: str,
    progress: bool = True,
    guard: tuple[tuple[str, ...], str] | None = None,
    pose=None,
) -> tuple[int, int]:
    """``stream.clean_file`` with a progress bar (bytes) on stderr for big files;
    ``guard`` (names, label): refuse a block of values far outside [0, 1]; ``pose``: the
    head/eye angles' cleaner, or None (its output gets the finite check only)."""
    import functools

    from tqdm import tqdm

    from faceclean.adjust import check_range
    from faceclean.filters.base import check_finite
    from faceclean.io import stream

    cleaner.reset()

    def check(inp, outp) -> None:
        if guard is not None:
            check_range(inp, *guard)
        check_finite(inp, outp, cleaner.name)

    size = src.stat().st_size
    angles = {}
    if pose is not None:
        pose.reset()
        angles = {
            "pose_step": pose.step,
            "pose_check": functools.partial(check_finite, name=pose.name),
        }
    if size < PROGRESS_BYTES or not progress:
        return stream.clean_file(src, out, cleaner.step, fmt, check=check, **angles)
    with tqdm(total=size, unit="B", unit_scale=True, file=sys.stderr, leave=False) as bar:
        return stream.clean_file(src, out, cleaner.step, fmt, bar.update, check, **angles)


def clean_with_progress(cleaner: Cleaner, anim: Animation) -> Animation:
    """``cleaner.clean(anim)``, with a progress bar on stderr for long stream cleans.

    A stream cleaner that keeps the base batch path is stepped here frame by frame, which
    is the same computation (reset, then step every valid frame).
    """
    import numpy as np
    from tqdm import tqdm

    from faceclean.filters.base import Cleaner, check_finite

    valid = np.flatnonzero(anim.valid)
    if cleaner.offline or type(cleaner).clean is not Cleaner.clean or len(valid) < PROGRESS_FRAMES:
        return cleaner.clean(anim)
    cleaner.reset()
    out = np.full_like(anim.values, np.nan)
    for i in tqdm(valid, unit="frame", file=sys.stderr, leave=False, desc="cleaning"):
        out[i] = cleaner.step(anim.values[i], anim.times[i])
    check_finite(anim.values, out, cleaner.name)
    return anim.with_values(out)
