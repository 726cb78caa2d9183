"""Clean a row-format file (Live Link Face CSV, plain CSV) in constant memory.

A causal cleaner needs only the past, so a huge take can go through it in blocks of
lines: read a block, parse it with the format's own row parser, step the cleaner over
its valid frames, write the cleaned block to the atomic output, forget it. Memory is
one block (``BLOCK`` lines) whatever the file's size. The bytes written are exactly
those of the in-memory path (``io.load``, ``cleaner.clean``, ``io.save``; a test
proves it): the same parsers, the same writers, the same cleaner calls in the same
order. A refused file (a bad row half-way) leaves no output: the temporary file is
removed and an existing OUT is untouched.

The cleaner is a plain ``step(x, t) -> x`` callable over one frame (M,) at t s, reset by
the caller; a Live Link file's head/eye angles go through ``pose_step`` (the same kind of
callable, over the angle columns in file order, ``angle_names``) on the frames that carry
blendshapes, as ``filters.rotation.clean_pose`` does in memory. ``check(input, output)``
(R, M), when given, sees every block before it is written and raises to refuse the file
(the cleaner's finite check, filters/base.py). Only a cleaner whose ``clean`` is
reset-then-step can stream (the caller asks ``Cleaner.stepwise``; offline cleaners and
cleaners with their own batch path load the whole file), and only into the same format
(``can_stream``).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np

from faceclean.channels import pose_name
from faceclean.errors import FacecleanError
from faceclean.io import livelink_csv, plain_csv, source
from faceclean.io.atomic import atomic_open
from faceclean.timing import Restarts

BLOCK = 4096  # lines per block
FORMATS = ("livelink", "csv")

Progress = Callable[[int], None]  # called with the bytes consumed since the last call
Step = Callable[[np.ndarray, float], np.ndarray]  # one frame (M,) at t s -> cleaned (M,)
Check = Callable[[np.ndarray, np.ndarray], None]  # (input, output) (R, M); raises to refuse
Steps = Callable[[np.ndarray, np.ndarray], np.ndarray]  # times (R,), frames (R, M) -> (R, M)


def can_stream(fmt_in: str | None, fmt_out: str | None) -> bool:
    """Whether ``clean_file`` applies to these formats: a row format in and out."""
    return fmt_in in FORMATS and fmt_out == fmt_in


def channel_names(path: str | os.PathLike, fmt: str) -> tuple[str, ...]:
    """The channel names of a row-format file, from its header line alone."""
    p = Path(path)
    with source.open_binary(p) as f:
        first = next(source.iter_lines(f), b"")
    try:
        if fmt == "livelink":
            if not livelink_csv.sniff(first):
                raise FacecleanError(f"{p.name}: not a Live Link Face CSV")
            return livelink_csv.parse_header(first, p.name).names
        head = plain_csv.header_line(first)
        if not plain_csv.sniff(head):
            raise FacecleanError(f"{p.name}: not a plain CSV (no 'time' column in the header)")
        names = plain_csv.parse_header(head, p.name)[1]
        angles = set(plain_csv.angle_columns(names).tolist())
        return tuple(n for j, n in enumerate(names) if j not in angles)
    except UnicodeDecodeError as e:
        raise FacecleanError(f"{p.name}: header is not UTF-8 ({e})") from None


def angle_names(path: str | os.PathLike, fmt: str = "livelink") -> tuple[str, ...]:
    """The head/eye angle columns of a row-format file (Live Link spelling, file order)."""
    p = Path(path)
    with source.open_binary(p) as f:
        first = next(source.iter_lines(f), b"")
    if fmt == "csv":
        names = plain_csv.parse_header(plain_csv.header_line(first), p.name)[1]
        return tuple(pose_name(names[j]) for j in plain_csv.angle_columns(names))
    head = livelink_csv.parse_header(first, p.name)
    return tuple(n for j in head.pose_cols if (n := pose_name(head.fields[j])) is not None)


def clean_file(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    step: Step,
    fmt: str,
    progress: Progress | None = None,
    check: Check | None = None,
    pose_step: Step | None = None,
    pose_check: Check | None = None,
    steps: Steps | None = None,
) -> tuple[int, int]:
    """Clean ``src`` (format ``fmt``) into ``dst`` block by block with ``step`` (a reset
    cleaner's) and, for a Live Link file's angles, ``pose_step``; (frames, missing
    frames). ``check``: see the module docstring; ``pose_check`` sees the angles.
    ``steps``: the same cleaner's ``Stepper.steps`` (a block's valid frames in one call,
    the same numbers), used instead of ``step`` when given.

    OUT may be IN: the output replaces it only once the whole file is through.
    """
    if fmt not in FORMATS:
        raise FacecleanError(f"cannot stream format {fmt!r} (only {', '.join(FORMATS)})")
    p = Path(src)
    rows = _Rows(step, check, steps, Restarts(p.name))
    pose = None if pose_step is None else _Rows(pose_step, pose_check)
    with source.open_binary(p) as f, atomic_open(dst, "wb") as out:
        try:
            if fmt == "livelink":
                return _livelink(p.name, _counted(f, progress), out, rows, pose)
            return _plain(p.name, _counted(f, progress), out, rows, pose)
        except UnicodeDecodeError as e:
            raise FacecleanError(f"{p.name}: not UTF-8 text ({e})") from None


def _counted(f: BinaryIO, progress: Progress | None) -> Iterator[list[bytes]]:
    """Blocks of up to BLOCK lines; reports bytes consumed to ``progress``."""
    block: list[bytes] = []
    size = 0
    for line in source.iter_lines(f):
        block.append(line)
        size += len(line)
        if len(block) == BLOCK:
            yield block
            if progress is not None:
                progress(size)
            block, size = [], 0
    if block:
        yield block
        if progress is not None:
            progress(size)


class _Rows:
    """Cleaned (R, M) values of a block: valid rows stepped in order, missing rows NaN
    (as Cleaner.clean), then ``check``ed. ``steps``: the valid rows in one call."""

    def __init__(self, step: Step, check: Check | None, steps: Steps | None = None,
                 restarts: Restarts | None = None) -> None:  # fmt: skip
        self.step, self.check, self.steps, self.restarts = step, check, steps, restarts

    def __call__(self, times: np.ndarray, values: np.ndarray) -> np.ndarray:
        out = np.full_like(values, np.nan)
        valid = ~np.all(np.isnan(values), axis=1) if values.shape[1] else np.ones(len(values), bool)
        if self.restarts is not None:  # times that restart: refused, not held still
            self.restarts.see(times[valid])
        if self.steps is not None:
            rows = np.flatnonzero(valid)
            if len(rows):
                out[rows] = self.steps(times[rows], values[rows])
        else:
            for i in np.flatnonzero(valid):
                out[i] = self.step(values[i], times[i])
        if self.check is not None:
            self.check(values, out)  # as Cleaner.clean: an erasing cleaner fails
        return out


def _livelink(
    name: str,
    blocks: Iterator[list[bytes]],
    out: BinaryIO,
    clean_rows: _Rows,
    clean_pose: _Rows | None = None,
):
    first = next(blocks, None)
    if not first or not livelink_csv.sniff(first[0]):
        raise FacecleanError(f"{name}: not a Live Link Face CSV (no Timecode,BlendshapeCount)")
    head = livelink_csv.parse_header(first[0], name)
    n_fields = len(head.fields)
    cols = head.columns - 2
    angles = np.array([j for j in head.pose_cols if pose_name(head.fields[j])], dtype=int)
    out.write(first[0])
    pending: list[tuple[list[bytes], tuple]] = []  # blocks parsed before the decimals are known
    decimals: int | None = None
    start = previous = None
    wraps = frames = missing_total = 0
    done = 1  # lines before the current block
    sample: list[np.ndarray] = []  # cells of the first DECIMALS_SAMPLE valid rows

    def flush(lines: list[bytes], parsed: tuple) -> None:
        nonlocal start, previous, wraps, frames, missing_total
        first_line, rows, missing, stamps, table = parsed
        if rows:
            absolute = np.array(stamps)
            if start is None:
                start = previous = float(absolute[0])
            times, wraps = livelink_csv.relative_times(absolute, start, previous, wraps)
            previous = float(absolute[-1])
            numbers = livelink_csv.parse_numbers(table, name)
            values = numbers[:, cols]
            new = clean_rows(times, values)
            local = np.array(rows) - first_line
            gone = np.array(missing, bool)
            livelink_csv.patch_lines(lines, local, gone, head.columns, values, new, decimals)
            if clean_pose is not None and len(angles):
                old = numbers[:, angles - 2]  # (R, A) rad
                seen = ~np.all(np.isnan(values), axis=1) if values.shape[1] else ~gone
                steps = np.where(seen[:, None], old, np.nan)  # tracking loss: missing
                cleaned = clean_pose(times, steps)
                livelink_csv.patch_lines(lines, local, gone, angles, old, cleaned, decimals)
            frames += len(rows)
            missing_total += int(np.sum(missing))
        out.write(b"".join(lines))

    blocks_iter = _chain([first[1:]], blocks)
    for lines in blocks_iter:
        rows, missing, stamps, table = livelink_csv.parse_rows(lines, done, n_fields, name)
        parsed = (done, rows, missing, stamps, table)
        done += len(lines)
        if decimals is None:
            sample.append(table[~np.array(missing, bool)][:, cols])
            pending.append((lines, parsed))
            if sum(len(s) for s in sample) < livelink_csv.DECIMALS_SAMPLE:
                continue
            decimals = _decimals(sample)
            for item in pending:
                flush(*item)
            pending.clear()
        else:
            flush(lines, parsed)
    if decimals is None:
        decimals = _decimals(sample)
        for item in pending:
            flush(*item)
    if not frames:
        raise FacecleanError(f"{name}: no frames")
    return frames, missing_total


def _decimals(sample: list[np.ndarray]) -> int:
    cells = [s for s in sample if len(s)]
    if not cells:
        return livelink_csv.DECIMALS
    width = max(c.dtype.itemsize for c in cells)
    table = np.concatenate([c.astype(f"S{width}") for c in cells])
    return livelink_csv.decimals_of(table[: livelink_csv.DECIMALS_SAMPLE])


def _plain(
    name: str,
    blocks: Iterator[list[bytes]],
    out: BinaryIO,
    clean_rows: _Rows,
    clean_pose: _Rows | None = None,
):
    first = next(blocks, None)
    head = plain_csv.header_line(first[0]) if first else b""
    if not first or not plain_csv.sniff(head):
        raise FacecleanError(f"{name}: not a plain CSV (no 'time' column in the header)")
    t_col, names = plain_csv.parse_header(head, name)
    angles = plain_csv.angle_columns(names)  # written after the channels, as io.save does
    cols = np.array([j for j in range(len(names)) if j not in set(angles.tolist())], int)
    order = (*(names[j] for j in cols), *(pose_name(names[j]) for j in angles))
    out.write(plain_csv.header_text(order))
    done = frames = missing = 0
    for lines in _chain([first[1:]], blocks):
        stripped = [line.rstrip(b"\r\n") for line in lines]
        times, table, done = plain_csv.parse_rows(stripped, done, t_col, len(names) + 1, name)
        values = table[:, cols]
        new = clean_rows(times, values)
        if len(angles):
            pose = table[:, angles]  # (R, A) rad
            if clean_pose is not None:  # tracking loss: missing to the filter, kept as read
                seen = ~np.all(np.isnan(values), axis=1)[:, None]
                pose = np.where(seen, clean_pose(times, np.where(seen, pose, np.nan)), pose)
            new = np.concatenate([new, pose], axis=1)
        out.write(plain_csv.rows_text(times, new))
        frames += len(times)
        missing += int(np.all(np.isnan(values), axis=1).sum()) if values.shape[1] else 0
    if not frames:
        raise FacecleanError(f"{name}: no frames")
    return frames, missing


def _chain(head: list[list[bytes]], rest: Iterator[list[bytes]]) -> Iterator[list[bytes]]:
    yield from (b for b in head if b)
    yield from rest
