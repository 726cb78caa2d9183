"""Plain CSV: a ``time`` column in seconds plus one column per channel.

Header ``time,<name>,<name>,...``; one row per frame, comma-separated, ``\\n`` line
endings. Numbers are written with Python's ``repr(float)`` (the shortest text that reads
back to the same float64), so a write-read round trip is exact. An empty cell is NaN; a
missing frame (tracking loss) is a row whose channel cells are all empty. On read, the
``time`` column may sit anywhere (matched case-insensitively); every other column is a
channel, ARKit or not (unknown names pass through as channels), except head and eye
angles: a column named as Live Link names them (``HeadYaw``, ``leftEyePitch``, any case;
radians) is an angle, kept in ``meta["pose"]`` with ``meta["pose_names"]`` (Live Link
spelling), cleaned by the rotation filter rather than as a weight, and written back after
the channels. A file of angles alone keeps them as channels (there is nothing else).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import BinaryIO

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import pose_name, repeated
from faceclean.errors import FacecleanError
from faceclean.io import source

BLOCK = 4096  # lines read, or rows written, at a time


def header_line(line: bytes) -> bytes:
    """The first line of a file as ``sniff`` and ``parse_header`` take it: no BOM, no
    line ending."""
    return line.removeprefix(source.BOM).rstrip(b"\r\n")


def sniff(head: bytes) -> bool:
    """A plain CSV has a ``time`` column in its first line."""
    first = head.removeprefix(source.BOM).split(b"\n", 1)[0].rstrip(b"\r")
    return b"time" in (c.strip().strip(b'"').lower() for c in first.split(b","))


def read(path: str | os.PathLike) -> Animation:
    """Read a plain CSV; empty cells are NaN. The file is read and parsed ``BLOCK`` lines
    at a time (an hour at 60 fps is 220 MB of text: never whole in memory, nor its
    cells), then the blocks' arrays are joined once."""
    p = Path(path)
    size = source.regular(p).st_size
    if size > source.MAX_FILE:
        raise FacecleanError(
            f"{p.name}: {source.size_text(size)}, over the {source.size_text(source.MAX_FILE)} "
            "limit"
        )
    with source.open_binary(p) as f:
        lines = source.iter_lines(f)
        head = header_line(next(lines, b""))
        if not head or not sniff(head):
            raise FacecleanError(f"{p.name}: not a plain CSV (no 'time' column in the header)")
        t_col, names = parse_header(head, p.name)
        parts: list[tuple[np.ndarray, np.ndarray]] = []  # (times (R,), values (R, M))
        done, block = 0, []
        for line in lines:
            block.append(line.rstrip(b"\r\n"))
            if len(block) == BLOCK:
                t, v, done = parse_rows(block, done, t_col, len(names) + 1, p.name)
                parts.append((t.copy(), v))  # t: a column of the block's table (a view)
                block = []
        t, v, done = parse_rows(block, done, t_col, len(names) + 1, p.name)
        parts.append((t.copy(), v))
    times = np.concatenate([t for t, _ in parts])
    values = np.concatenate([v for _, v in parts])
    del parts
    angles = angle_columns(names)
    meta: dict = {"format": "csv"}
    if len(angles):
        meta.update(pose=values[:, angles], pose_names=[pose_name(names[j]) for j in angles])
        keep = [j for j in range(len(names)) if j not in set(angles.tolist())]
        names, values = tuple(names[j] for j in keep), values[:, keep]
    return Animation(times, values, names, meta)


def angle_columns(names: tuple[str, ...]) -> np.ndarray:
    """Indices into ``names`` of the head/eye angle columns (none when nothing else is
    there: a file of angles alone keeps them as its channels)."""
    angles = np.array([j for j, n in enumerate(names) if pose_name(n) is not None], int)
    return angles if len(angles) < len(names) else np.zeros(0, int)


def parse_header(line: bytes, label: str) -> tuple[int, tuple[str, ...]]:
    """The header line (no BOM) of file ``label`` -> (index of the time column, channel
    names); a channel named twice (a case apart: one ARKit channel) is refused."""
    cells = line.split(b",")
    source.check_cells(cells, f"{label}: header", source.MAX_NAME)
    header = [c.strip().strip(b'"').decode("utf-8") for c in cells]
    t_col = [h.lower() for h in header].index("time")
    names = tuple(h for j, h in enumerate(header) if j != t_col)
    if (twice := repeated(names)) is not None:
        raise FacecleanError(f"{label}: channel {twice!r} is given twice: name each once")
    return t_col, names


def parse_rows(
    lines: list[bytes], done: int, t_col: int, n_fields: int, label: str
) -> tuple[np.ndarray, np.ndarray, int]:
    """Data lines -> (times (R,) s, values (R, M), rows read so far). Blank lines are
    skipped; ``done`` rows were read before these (for the row numbers in errors)."""
    rows = [line.split(b",") for line in lines if line.strip()]
    for k, row in enumerate(rows, start=done):
        rows[k - done] = row = source.short_cells(row, f"{label}: row {k + 1}")
        if len(row) != n_fields:
            raise FacecleanError(
                f"{label}: row {k + 1} has {len(row)} fields, the header has {n_fields}"
            )
    table = np.array(rows, dtype=bytes).reshape(len(rows), n_fields)
    cells = np.where(np.char.strip(table) == b"", b"nan", table)
    try:
        numbers = cells.astype(np.float64)
    except ValueError:  # numpy's words name its own types: say the cell
        raise FacecleanError(f"{label}: {_not_a_number(cells, done)}") from None
    times = numbers[:, t_col]
    source.check_times(times, label, first=done)
    keep = [j for j in range(n_fields) if j != t_col]
    return times, numbers[:, keep], done + len(rows)


def write(anim: Animation, f: BinaryIO) -> None:
    """Write ``time``, every channel, then the head/eye angles (``meta["pose"]``, when
    the take has them), repr-exact; NaN as an empty cell."""
    pose, pose_names = anim.meta.get("pose"), list(anim.meta.get("pose_names", ()))
    if pose is None or not pose_names:
        f.write(header_text(anim.names))
        for a in range(0, anim.n_frames, BLOCK):  # streamed: no text as large as the take
            f.write(rows_text(anim.times[a : a + BLOCK], anim.values[a : a + BLOCK]))
        return
    f.write(header_text((*anim.names, *(str(n) for n in pose_names))))
    pose = np.asarray(pose, float)
    for a in range(0, anim.n_frames, BLOCK):
        cells = np.concatenate([anim.values[a : a + BLOCK], pose[a : a + BLOCK]], 1)
        f.write(rows_text(anim.times[a : a + BLOCK], cells))


def header_text(names: tuple[str, ...]) -> bytes:
    """The header line for channels ``names``; a name a CSV cannot hold, or a header its
    reader would refuse (``source.MAX_FIELDS``, ``MAX_NAME``), is refused."""
    if len(names) + 1 > source.MAX_FIELDS:
        raise FacecleanError(f"a CSV holds at most {source.MAX_FIELDS - 1} channels, this take "
                             f"has {len(names)}: write .npz or .json")  # fmt: skip
    for n in names:
        if "," in n or "\n" in n or "\r" in n:
            raise FacecleanError(f"channel name {n!r} cannot go in a CSV header")
        if len(n.encode("utf-8")) > source.MAX_NAME:
            raise FacecleanError(f"channel name {n[:40]!r}... is over {source.MAX_NAME} bytes, "
                                 "more than a CSV header holds: write .npz or .json")  # fmt: skip
    return (",".join(("time", *names)) + "\n").encode("utf-8")


def rows_text(times: np.ndarray, values: np.ndarray) -> bytes:
    """Rows for (R,) times and (R, M) values: repr-exact numbers, NaN as an empty cell."""
    out = []
    for t, row in zip(times.tolist(), values.tolist(), strict=True):
        cells = ["" if v != v else repr(v) for v in row]  # v != v: NaN
        out.append(",".join([repr(t), *cells]) + "\n")
    return "".join(out).encode("utf-8")


def _not_a_number(cells: np.ndarray, done: int) -> str:
    """Where the first cell of ``cells`` (R, F) bytes that is not a number is."""
    for k, row in enumerate(cells):
        for j, c in enumerate(row):
            try:
                float(c)
            except ValueError:
                text = c.decode("utf-8", "backslashreplace")[:40]
                return f"row {done + k + 1}, field {j + 1}: {text!r} is not a number"
    return "a value is not a number"
