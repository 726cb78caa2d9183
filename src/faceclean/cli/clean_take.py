"""One take through ``faceclean clean``: ``clean_one(args, IN, OUT)`` and the pieces a batch
shares with it (the cleaner and the levels the options name, the same-file check). The
command's options and its batch mode are cli/clean.py's and cli/clean_batch.py's; both
come here for a take.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from faceclean.cli import options

if TYPE_CHECKING:
    from pathlib import Path

    from faceclean.animation import Animation
    from faceclean.filters.base import Stepper
    from faceclean.resolve import Choice

PROGRESS_FRAMES = 5000  # show a progress bar from this many frames on
PROGRESS_BYTES = 8 << 20  # ... or, when streaming a file, from this many bytes on
ROW_BYTES = 24  # bytes a channel's cell takes at most, about (repr-exact: ~20 and a comma):
# a streamed file's frames, at least about size / (ROW_BYTES M), decide its compiled path


def clean_one(args: argparse.Namespace, input: str, output: str, progress: bool = True) -> str:
    """Clean one file as the options ask; the line that says what was written."""
    from pathlib import Path

    from faceclean import io
    from faceclean.adaptation import clean_calibrated
    from faceclean.adjust import Adjusted, check_range
    from faceclean.filters import rotation
    from faceclean.io import stream
    from faceclean.timing import refuse_restarts

    choice = options.choice(args)
    src = Path(input)
    in_place = getattr(args, "in_place", False)
    io.paths.onto_input(input, output, in_place, "a raw take is never overwritten")
    done = io.paths.verb(output)  # "replaced": said before the file is gone
    fmt_in = io.detect(src) if src.is_file() else None
    if getattr(args, "compress", False):  # refused before any work, the streamed path too
        io.save_options(output, fmt_in, args.fmt, compress=True)
    fmt_out = io.output_format(output, fmt_in, args.fmt) if fmt_in in stream.FORMATS else None
    if stream.can_stream(fmt_in, fmt_out):
        names = stream.channel_names(src, fmt_in)
        cleaner, what = build_cleaner(choice, names)
        if names and cleaner.stepwise:
            adjust = build_levels(args, choice, names)
            _unread(args, adjust, cleaner, what)
            if not adjust.is_identity:
                cleaner = Adjusted(cleaner, adjust, names)
            guard = (names, input, args.scale)
            cleaner = _watched(args, cleaner, names, input)
            pose = None
            if angles := stream.angle_names(src, fmt_in):
                pose = choice.build_pose(angles)
            frames, missing = _stream(src, output, cleaner, fmt_in, progress, guard, pose,
                                      len(names))  # fmt: skip
            return _line(done, output, frames, missing, names, what, adjust, choice, pose)
    anim = io.load(src)
    refuse_restarts(anim, src.name)  # as the stream's: never held still
    for a in range(0, max(anim.n_frames, 1), stream.BLOCK):  # as the stream's, by block
        check_range(anim.values[a : a + stream.BLOCK], anim.names, input, args.scale)
    _signature(args, anim, input)
    cleaner, what = build_cleaner(choice, anim.names)
    adjust = build_levels(args, choice, anim.names)
    _unread(args, adjust, cleaner, what)
    # no level mapping: the take itself, not a copy (an hour is 92 MB; issue 38)
    run = (lambda mapped: clean_with_progress(cleaner, mapped)) if progress else None
    cleaned = rotation.clean_pose(clean_calibrated(cleaner, anim, adjust, run), choice.build_pose)
    io.save(cleaned, output, fmt=args.fmt, compress=getattr(args, "compress", False))
    angles = rotation.pose_columns(anim)[1]
    missing = int((~anim.valid).sum())
    return _line(done, output, anim.n_frames, missing, anim.names, what, adjust, choice, angles)


def _signature(args: argparse.Namespace, anim: Animation, label: str) -> None:
    """``--tracker mediapipe`` on a take that does not look raw: one warning line."""
    if getattr(args, "tracker", None) != "mediapipe":
        return
    from faceclean.trackers import signature

    why = signature.judge(anim.values, anim.names)
    if why is not None:
        print(signature.warning(why, label), file=sys.stderr)


def _watched(args: argparse.Namespace, cleaner, names, label: str):
    """The streamed form of ``_signature``: the cleaner, watching what it steps."""
    if getattr(args, "tracker", None) != "mediapipe":
        return cleaner
    from faceclean.trackers import signature

    def warn(why: str) -> None:
        print(signature.warning(why, label), file=sys.stderr)

    return signature.Watch(cleaner, names, warn)


def build_levels(args: argparse.Namespace, choice: Choice, names: tuple[str, ...]):
    """The level mapping: ``--calibration``, then the ``--set`` level items on top."""
    from faceclean.adjust import Adjust

    base = options.calibration(args) or Adjust()
    levels = base.merged(choice.adjust(names))
    scale = getattr(args, "scale", None)
    return levels if scale is None else levels.scaled(scale)


def _unread(args: argparse.Namespace, adjust, cleaner: Stepper, what: str) -> None:
    """One warning line when --calibration changes nothing for this cleaner."""
    from faceclean.adaptation import unread

    if why := unread(adjust, cleaner):
        print(f"faceclean: warning: --calibration {args.calibration} {why}"
              f"; {what} reads none ('calibrate --rom --tracker mediapipe' writes levels)",
              file=sys.stderr)  # fmt: skip


def build_cleaner(choice: Choice, names: tuple[str, ...]) -> tuple[Stepper, str]:
    """The cleaner the options chose, for these channels, and how to name it."""
    return choice.build(names), choice.source


def _line(
    done: str,
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
        f"{done} {out}: {frames} frames"
        + (f" ({missing} missing)" if missing else "")
        + f", {len(names)} channels, cleaned with {what}"
        + (f" after levels on {n} channels" if n else "")
        + (f"; {n_angles} head/eye angles with {choice.pose_source}" if n_angles else "")
    )


def _stream(
    src: Path,
    out: str,
    cleaner: Stepper,
    fmt: str,
    progress: bool = True,
    guard: tuple[tuple[str, ...], str, float | None] | None = None,
    pose=None,
    channels: int = 1,
) -> tuple[int, int]:
    """``stream.clean_file`` with a progress bar (bytes) on stderr for big files;
    ``guard`` (names, label, --scale): refuse a block of values far outside [0, 1];
    ``pose``: the head/eye angles' cleaner, or None (its output gets the finite check
    only). A file of ``channels`` channels long enough for the whole-take path
    (filters/compiled.py ``for_take``) goes through ``cleaner.steps`` a block at a time:
    runs of frames compiled, the same numbers."""
    import functools

    from tqdm import tqdm

    from faceclean.adjust import check_range
    from faceclean.filters import compiled
    from faceclean.filters.base import check_finite
    from faceclean.io import stream

    cleaner.reset()

    def check(inp, outp) -> None:
        if guard is not None:
            check_range(inp, *guard)
        check_finite(inp, outp, cleaner.name)

    size = src.stat().st_size
    if compiled.for_take(size // (ROW_BYTES * max(channels, 1))):
        steps = {"steps": cleaner.steps}  # a long file: runs of frames compiled (issue 38)
    else:
        steps = {}
    angles = {}
    if pose is not None:
        pose.reset()
        angles = {
            "pose_step": pose.step,
            "pose_check": functools.partial(check_finite, name=pose.name),
        }
    if size < PROGRESS_BYTES or not progress:
        return stream.clean_file(src, out, cleaner.step, fmt, check=check, **angles, **steps)
    with tqdm(total=size, unit="B", unit_scale=True, file=sys.stderr, leave=False) as bar:
        return stream.clean_file(src, out, cleaner.step, fmt, bar.update, check, **angles, **steps)


def clean_with_progress(cleaner: Stepper, anim: Animation) -> Animation:
    """``cleaner.clean(anim)``, with a progress bar on stderr for long stream cleans.

    A stream cleaner that keeps the base batch path is stepped here frame by frame, which
    is the same computation (reset, then step every valid frame); one with
    ``StreamCleaner.clean`` reports its progress itself, unless its runs go compiled.
    """
    import numpy as np

    from faceclean.filters.base import Stepper, StreamCleaner, check_finite

    own = type(cleaner).clean
    stepped = own in (Stepper.clean, StreamCleaner.clean)
    if cleaner.offline or not stepped or anim.n_frames < PROGRESS_FRAMES:
        return cleaner.clean(anim)  # short, offline, or its own (the LSTM's, a map's): no bar
    valid = np.flatnonzero(anim.valid)
    fast = own is StreamCleaner.clean and cleaner.compiles(len(valid))
    if len(valid) < PROGRESS_FRAMES or fast:  # compiled: ~2 million frames a second, no bar
        return cleaner.clean(anim)
    from tqdm import tqdm

    if own is StreamCleaner.clean:
        with tqdm(total=len(valid), unit="frame", file=sys.stderr, leave=False,
                  desc="cleaning") as bar:  # fmt: skip
            return cleaner.clean(anim, progress=bar.update)
    cleaner.reset()
    out = np.full_like(anim.values, np.nan)
    for i in tqdm(valid, unit="frame", file=sys.stderr, leave=False, desc="cleaning"):
        out[i] = cleaner.step(anim.values[i], anim.times[i])
    check_finite(anim.values, out, cleaner.name)
    return anim.with_values(out)
