"""Plain CSV: a ``time`` column in seconds plus one column per channel.

Header ``time,<name>,<name>,...``; one row per frame, comma-separated, ``\\n`` line
endings. Numbers are written with Python's ``repr(float)`` (the shortest text that reads
back to the same float64), so a write-read round trip is exact. An empty cell is NaN; a
missing frame (tracking loss) is a row whose channel cells are all empty. On read, the
``time`` column may sit anywhere (matched case-insensitively); every other column is a
channel, ARKit or not (unknown names pass through as channels).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import BinaryIO

import numpy as np

from faceclean.animation import Animation
from faceclean.errors import FacecleanError

_BOM = b"\xef\xbb\xbf"


def sniff(head: bytes) -> bool:
    """A plain CSV has a ``time`` column in its first line."""
    first = head.removeprefix(_BOM).split(b"\n", 1)[0].rstrip(b"\r")
    return b"time" in (c.strip().strip(b'"').lower() for c in first.split(b","))


def read(path: str | os.PathLike) -> Animation:
    """Read a plain CSV; empty cells are NaN."""
    p = Path(path)
    lines = p.read_bytes().removeprefix(_BOM).splitlines()
    if not lines or not sniff(lines[0]):
        raise FacecleanError(f"{p.name}: not a plain CSV (no 'time' column in the header)")
    header = [c.strip().strip(b'"').decode("utf-8") for c in lines[0].split(b",")]
    t_col = [h.lower() for h in header].index("time")
    rows = [line.split(b",") for line in lines[1:] if line.strip()]
    for k, row in enumerate(rows):
        if len(row) != len(header):
            raise FacecleanError(
                f"{p.name}: row {k + 1} has {len(row)} fields, the header has {len(header)}"
            )
    table = np.array(rows, dtype=bytes).reshape(len(rows), len(header))
    try:
        numbers = np.where(np.char.strip(table) == b"", b"nan", table).astype(np.float64)
    except ValueError as e:
        raise FacecleanError(f"{p.name}: a value is not a number ({e})") from None
    times = numbers[:, t_col]
    if not np.isfinite(times).all():
        raise FacecleanError(f"{p.name}: every row needs a finite time")
    keep = [j for j in range(len(header)) if j != t_col]
    return Animation(times, numbers[:, keep], tuple(header[j] for j in keep), {"format": "csv"})


def write(anim: Animation, f: BinaryIO) -> None:
    """Write ``time`` and every channel, repr-exact; NaN as an empty cell."""
    for n in anim.names:
        if "," in n or "\n" in n or "\r" in n:
            raise FacecleanError(f"channel name {n!r} cannot go in a CSV header")
    out = [",".join(("time", *anim.names)) + "\n"]
    for t, row in zip(anim.times.tolist(), anim.values.tolist(), strict=True):
        cells = ["" if v != v else repr(v) for v in row]  # v != v: NaN
        out.append(",".join([repr(t), *cells]) + "\n")
    f.write("".join(out).encode("utf-8"))
