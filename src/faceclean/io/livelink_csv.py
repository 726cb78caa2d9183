"""Live Link Face CSV (Epic's iPhone app export), read and written back byte for byte.

Header: ``Timecode,BlendshapeCount,`` (or ``BlendShapeCount``), then blendshape names in
PascalCase in the app's own order, then 9 head/eye angles. Columns are mapped by name;
only columns whose name is an ARKit blendshape are channels, every other column is
``meta["pose"]`` (N, P) (the head/eye angles in radians, as written) with
``meta["pose_names"]``; the angles are cleaned by the rotation filter
(filters/rotation.py), the rest passes through.

Timecode ``HH:MM:SS:FF.fff``: FF frames at 60 fps plus a fractional sub-frame ``.fff``::

    seconds = 3600 HH + 60 MM + SS + (FF + 0.fff) / 60

``times`` start at 0 on the first row (its absolute time of day is
``meta["timecode_start"]``); a timecode more than 12 h below the previous one wrapped past
midnight and counts on from 24:00:00.

A row with ``BlendshapeCount`` 0 and no values (``16:48:52:29.134,0``) is a missing frame:
an all-NaN row, written back as it was.

Writing an animation read from such a file changes only the text of blendshape values
and angles (``meta["pose"]``) that changed: the header, timecodes, counts, other
columns, column order, line endings, blank lines and the final newline (or its absence)
stay byte for byte. A changed value is
written with the source's number of decimals (10 in the app's files); a NaN keeps the
original text. Any other animation is written as a fresh file: 52 blendshapes in the app's
order, angles from ``meta["pose"]`` or 0, then any other pose column (e.g. a relay
recording's ``ArrivalTime``), timecodes synthesised from ``times``
(+ ``meta["timecode_start"]``).
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52, canonical, pascal
from faceclean.errors import FacecleanError
from faceclean.io import source as bounded
from faceclean.io.json_format import refuse_infinite

FPS = 60.0  # the timecode's frame rate, Hz
DAY = 86400.0  # s
DECIMALS = 10  # the app's number format for fresh files
DECIMALS_SAMPLE = 50  # rows whose cells decide the decimals of changed values

# The app's column order (differs from ARKit's: JawRight before JawLeft, MouthRight first).
ORDER: tuple[str, ...] = tuple(
    pascal(n)
    for n in ARKIT52[:15] + ("jawRight", "jawLeft") + ARKIT52[17:21]
    + ("mouthRight", "mouthLeft") + ARKIT52[23:]
)  # fmt: skip
ANGLES: tuple[str, ...] = (
    "HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
    "RightEyeYaw", "RightEyePitch", "RightEyeRoll",
)  # fmt: skip

# HH:MM:SS:FF.fff, each field 1-2 digits (range-checked), at most 9 decimals of a frame
_TIMECODE = re.compile(rb"^\s*(\d{1,2}):(\d{1,2}):(\d{1,2})[:;.](\d{1,2}(?:\.\d{0,9})?)\s*$")


@dataclass(frozen=True, eq=False)
class Source:
    """What the writer needs to give the file back: kept in ``meta["livelink"]``."""

    lines: tuple[bytes, ...]  # every line with its own ending
    rows: np.ndarray  # (N,) index into lines of each frame
    missing: np.ndarray  # (N,) bool, rows without values
    columns: np.ndarray  # (M,) field index of each channel
    names: tuple[str, ...]  # (M,) channel names as spelled
    values: np.ndarray  # (N, M) the values as read
    times: np.ndarray  # (N,) s
    decimals: int
    pose_columns: np.ndarray | None = None  # (P,) field index of each pose column
    pose: np.ndarray | None = None  # (N, P) the pose cells as read


def sniff(head: bytes) -> bool:
    """A Live Link Face CSV starts ``Timecode,BlendshapeCount``."""
    return head.removeprefix(bounded.BOM).lower().startswith(b"timecode,blendshapecount")


def timecode_seconds(text: bytes | str) -> float:
    """``HH:MM:SS:FF.fff`` -> seconds of the day (FF at 60 fps, .fff a sub-frame)."""
    raw = text.encode() if isinstance(text, str) else text
    m = _TIMECODE.match(raw)
    if m is None:
        raise FacecleanError(f"bad timecode {raw[:40].decode(errors='replace')!r}")
    h, mi, s = (int(g) for g in m.groups()[:3])
    ff = float(m.group(4))
    if h > 23 or mi > 59 or s > 59 or ff >= FPS:  # a time of day: no 99:99:99:99.999
        raise FacecleanError(
            f"bad timecode {raw[:40].decode(errors='replace')!r} (not a time of day)"
        )
    return 3600.0 * h + 60.0 * mi + s + ff / FPS


def timecode_text(seconds: float) -> str:
    """Seconds of the day -> ``HH:MM:SS:FF.fff`` (wraps at 24 h)."""
    sub = int(round(seconds * FPS * 1000.0))  # thousandths of a frame
    frame, frac = divmod(sub, 1000)
    sec, ff = divmod(frame, int(FPS))
    h, rest = divmod(sec, 3600)
    mi, s = divmod(rest, 60)
    return f"{h % 24:02d}:{mi:02d}:{s:02d}:{ff:02d}.{frac:03d}"


def read(path: str | os.PathLike) -> Animation:
    """Read a Live Link Face CSV; missing frames become all-NaN rows."""
    p = Path(path)
    data = bounded.read_bytes(p)
    lines = tuple(data.splitlines(keepends=True))
    if not lines or not sniff(lines[0]):
        raise FacecleanError(f"{p.name}: not a Live Link Face CSV (no Timecode,BlendshapeCount)")
    head = parse_header(lines[0], p.name)
    rows, missing, stamps, table = parse_rows(lines[1:], 1, len(head.fields), p.name)
    if not rows:
        raise FacecleanError(f"{p.name}: no frames")
    numbers = parse_numbers(table, p.name)
    values = numbers[:, head.columns - 2]
    pose = numbers[:, head.pose_cols - 2]
    absolute = np.array(stamps)
    times, _ = relative_times(absolute, absolute[0], absolute[0], 0)
    source = Source(
        lines=lines,
        rows=np.array(rows),
        missing=np.array(missing, bool),
        columns=head.columns,
        names=head.names,
        values=values.copy(),
        times=times.copy(),
        decimals=decimals_of(table[~np.array(missing, bool)][:DECIMALS_SAMPLE, head.columns - 2]),
        pose_columns=head.pose_cols,
        pose=pose.copy(),
    )
    meta = {
        "format": "livelink",
        "livelink": source,
        "timecode_start": float(absolute[0]),
        "pose": pose,
        "pose_names": tuple(head.fields[j] for j in head.pose_cols),
    }
    return Animation(times, values, head.names, meta)


@dataclass(frozen=True, eq=False)
class Header:
    """The header line, parsed: which fields are channels and which pass through."""

    fields: tuple[str, ...]  # every column name, stripped
    columns: np.ndarray  # (M,) field index of each blendshape channel
    names: tuple[str, ...]  # (M,) channel names as spelled
    pose_cols: np.ndarray  # (P,) field index of every other column after the count


def parse_header(line: bytes, label: str) -> Header:
    """The first line -> Header; the first spelling of a blendshape wins, repeats pass."""
    raw = _content(line).removeprefix(bounded.BOM).split(b",")
    bounded.check_cells(raw, f"{label} line 1", bounded.MAX_NAME)
    fields = tuple(h.strip().decode("utf-8") for h in raw)
    columns, names, pose_cols = [], [], []
    seen: set[str] = set()
    for j, h in enumerate(fields[2:], start=2):
        c = canonical(h)
        if c is not None and c not in seen:
            seen.add(c)
            columns.append(j)
            names.append(h)
        else:
            pose_cols.append(j)
    if not columns:
        raise FacecleanError(f"{label}: no blendshape columns in the header")
    return Header(fields, np.array(columns), tuple(names), np.array(pose_cols, dtype=int))


def parse_rows(
    lines: Sequence[bytes], first: int, n_fields: int, label: str
) -> tuple[list[int], list[bool], list[float], np.ndarray]:
    """Data lines (``first``: index of lines[0] in the file) -> (row line indices, missing
    flags, timecodes in s of the day, (R, n_fields - 2) cells as bytes). Blank lines are
    skipped (they pass through on write)."""
    rows, missing, stamps, cells = [], [], [], []
    for k, line in enumerate(lines, start=first):
        fields = _content(line).split(b",")
        if fields == [b""]:
            continue  # blank line: passthrough
        if len(fields) > bounded.MAX_FIELDS:
            raise FacecleanError(f"{label} line {k + 1}: {len(fields)} fields")
        try:
            stamps.append(timecode_seconds(fields[0]))
        except FacecleanError as e:
            raise FacecleanError(f"{label} line {k + 1}: {e}") from None
        empty = len(fields) <= 2 or all(not f.strip() for f in fields[2:])
        if not empty and len(fields) != n_fields:
            raise FacecleanError(
                f"{label} line {k + 1}: {len(fields)} fields, the header has {n_fields}"
            )
        rows.append(k)
        missing.append(empty)
        where = f"{label} line {k + 1}"  # a 10 KB number: its short text in the table
        cells.append([b""] * (n_fields - 2) if empty else bounded.short_cells(fields[2:], where))
    table = np.array(cells, dtype=bytes).reshape(len(rows), n_fields - 2)
    return rows, missing, stamps, table


def parse_numbers(table: np.ndarray, label: str) -> np.ndarray:
    """(R, C) cells as bytes -> float64; an empty cell is NaN."""
    try:
        return np.where(np.char.strip(table) == b"", b"nan", table).astype(np.float64)
    except ValueError as e:
        raise FacecleanError(f"{label}: a value is not a number ({e})") from None


def relative_times(
    absolute: np.ndarray, start: float, previous: float, wraps: int
) -> tuple[np.ndarray, int]:
    """Timecodes (R,) s of the day -> s since the file's first row ``start``.

    A drop of more than 12 h from the row before (``previous`` for the first) is a wrap
    past midnight: count on from 24:00. ``wraps`` so far in, wraps after the block out.
    """
    n = wraps + np.cumsum(np.diff(absolute, prepend=previous) < -DAY / 2)
    return (absolute - start) + DAY * n, int(n[-1]) if len(n) else wraps


def write(anim: Animation, f: BinaryIO) -> None:
    """Write back into the source's text when there is one, else a fresh Live Link CSV.
    An infinite value has no cell a reader takes back: refused, before anything is written
    (a NaN cell of a frame is written empty, and read back as missing)."""
    refuse_infinite(anim.values, list(anim.names), "channel", "Live Link CSV")
    pose = np.asarray(anim.meta.get("pose", np.zeros((0, 0))), dtype=np.float64)
    if pose.ndim == 2 and pose.shape[0] == anim.n_frames:
        refuse_infinite(pose, list(anim.meta.get("pose_names", ())), "pose column", "Live Link CSV")
    src = anim.meta.get("livelink")
    if isinstance(src, Source) and _fits(src, anim):
        f.write(_patched(src, anim))
    else:
        f.write(_fresh(anim))


def _content(line: bytes) -> bytes:
    return line.rstrip(b"\r\n")


def decimals_of(sample: np.ndarray) -> int:
    """Most decimals among sample cells (bytes, any shape), else the app's 10: the
    precision the writer gives cleaned values."""
    best = 0
    for cell in sample.ravel():
        text = cell.strip()
        if b"e" in text.lower():
            continue
        _, dot, frac = text.partition(b".")
        if dot:
            best = max(best, len(frac))
    return best or DECIMALS


def _fits(src: Source, anim: Animation) -> bool:
    """Same frames at the same times: the source's text can carry the new values."""
    return anim.n_frames == len(src.rows) and np.array_equal(anim.times, src.times, equal_nan=True)


def _number(v: float, decimals: int) -> bytes:
    text = f"{v:.{decimals}f}"
    if text.startswith("-") and float(text) == 0.0:
        text = text[1:]  # no "-0.0000000000"
    return text.encode()


def _patched(src: Source, anim: Animation) -> bytes:
    new = src.values.copy()  # (N, M) in the source's columns
    by_name = {n: i for i, n in enumerate(src.names)}
    by_canon = {canonical(n): i for i, n in enumerate(src.names)}
    for j, n in enumerate(anim.names):
        i = by_name.get(n, by_canon.get(canonical(n)))
        if i is not None:
            new[:, i] = anim.values[:, j]
    lines = list(src.lines)
    patch_lines(lines, src.rows, src.missing, src.columns, src.values, new, src.decimals)
    pose = anim.meta.get("pose")
    if src.pose is not None and pose is not None and np.shape(pose) == src.pose.shape:
        old = src.pose
        patch_lines(lines, src.rows, src.missing, src.pose_columns, old, pose, src.decimals)
    return b"".join(lines)


def patch_lines(
    lines: list[bytes],
    rows: np.ndarray,
    missing: np.ndarray,
    columns: np.ndarray,
    old: np.ndarray,
    new: np.ndarray,
    decimals: int,
) -> None:
    """Replace, in place, the text of the cells whose value changed from ``old`` to ``new``
    (both (R, M)); rows (R,) index ``lines``. NaN and missing rows keep their text."""
    changed = ~np.isnan(new) & ~(new == old)
    changed[missing] = False
    for r in np.flatnonzero(changed.any(axis=1)):
        k = rows[r]
        line = lines[k]
        body = _content(line)
        fields = body.split(b",")
        for i in np.flatnonzero(changed[r]):
            fields[columns[i]] = _number(new[r, i], decimals)
        lines[k] = b",".join(fields) + line[len(body) :]


def _fresh(anim: Animation) -> bytes:
    """A new file in the app's layout (non-ARKit channels cannot be carried)."""
    arkit, _ = anim.arkit()
    order = [ARKIT52.index(canonical(n)) for n in ORDER]
    values = arkit[:, order]  # (N, 52) app order; a NaN cell is written empty (missing)
    pose = np.asarray(anim.meta.get("pose", np.zeros((0, 0))), dtype=np.float64)
    pose_names = tuple(anim.meta.get("pose_names", ()))
    fits = pose.ndim == 2 and pose.shape[0] == anim.n_frames
    plain = [n for n in pose_names if not set(n) & set(',\r\n"')]  # fits in a CSV header
    extra = tuple(n for n in plain if n not in ANGLES and fits)  # passthrough columns
    angles = np.zeros((anim.n_frames, len(ANGLES) + len(extra)))  # absent angles: 0
    if fits:
        for a, name in enumerate(ANGLES + extra):
            if name in pose_names:
                angles[:, a] = pose[:, pose_names.index(name)]
    start = float(anim.meta.get("timecode_start", 0.0))
    out = [",".join(("Timecode", "BlendshapeCount") + ORDER + ANGLES + extra).encode() + b"\n"]
    valid = anim.valid
    count = str(len(ORDER) + len(ANGLES)).encode()
    for i in range(anim.n_frames):
        tc = timecode_text(start + anim.times[i]).encode()
        if not valid[i]:
            out.append(tc + b",0\n")
            continue
        cells = [b"" if np.isnan(v) else _number(v, DECIMALS) for v in (*values[i], *angles[i])]
        out.append(b",".join([tc, count, *cells]) + b"\n")
    return b"".join(out)
