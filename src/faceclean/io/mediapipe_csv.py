"""MediaPipe blendshape CSV: what scripts around MediaPipe's Face Landmarker write.

Header: a time column, ``timestamp_ms`` (milliseconds, MediaPipe's own unit) or
``timestamp`` (unit from the median frame step: under 0.5 is seconds, under 500
milliseconds, else microseconds; a face tracker runs between 2 and 1000 fps), then one
column per category in MediaPipe's names (``_neutral``, ``eyeBlinkLeft``, ...). A
``frame`` column, where a script writes one, is kept but is not a channel. ``_neutral``
is not a blendshape: it is kept for the writer and not cleaned. A row with every score
empty is a missing frame (the face was lost). The times increase row by row, as
MediaPipe's VIDEO and LIVE_STREAM modes require, and fit its int64 microseconds: a
repeated, backwards or absurd timestamp is refused in one line naming the row, never
cleaned.

Written back with the same columns in the same order and the time in its own unit
(integers stay integers), so a cleaned file drops into the same tools.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import BinaryIO

import numpy as np

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.io import plain_csv, source

TIME_COLUMNS = ("timestamp_ms", "timestamp")
MAX_TIME = 2.0**63 * 1e-6  # s: MediaPipe's timestamps are int64 microseconds (~292 000 years)
KEPT = ("_neutral", "frame")  # columns carried through, never cleaned


def _header(line: bytes) -> list[str]:
    cells = plain_csv.header_line(line).split(b",")
    source.check_cells(cells, "header", source.MAX_NAME)
    return [c.strip().strip(b'"').decode("utf-8", "replace") for c in cells]


def sniff(head: bytes) -> bool:
    """A time column named ``timestamp_ms`` or ``timestamp`` (and no plain ``time``)."""
    first = head.removeprefix(source.BOM).split(b"\n", 1)[0]
    names = [h.lower() for h in _header(first)]
    return "time" not in names and any(t in names for t in TIME_COLUMNS)


def read(path: str | os.PathLike) -> Animation:
    p = Path(path)
    lines = source.read_bytes(p).removeprefix(source.BOM).splitlines()
    if not lines or not sniff(lines[0]):
        raise FacecleanError(f"{p.name}: not a MediaPipe CSV (no timestamp_ms/timestamp column)")
    header = _header(lines[0])
    lower = [h.lower() for h in header]
    t_name = next(t for t in TIME_COLUMNS if t in lower)
    t_col = lower.index(t_name)
    raw_t, numbers, _ = plain_csv.parse_rows(lines[1:], 0, t_col, len(header), p.name)
    rest = [h for j, h in enumerate(header) if j != t_col]
    kept = [j for j, h in enumerate(rest) if h.lower() in KEPT]
    chans = [j for j in range(len(rest)) if j not in kept]
    scale = 1e-3 if t_name == "timestamp_ms" else _unit(raw_t)
    times = raw_t * scale
    source.check_times(times, f"{p.name} ({t_name})", increasing=True, limit=MAX_TIME)
    values = numbers[:, chans]
    missing = np.isnan(values).all(axis=1) if chans else np.zeros(len(raw_t), bool)
    meta = {
        "format": "mediapipe",
        "mediapipe": {
            "header": header,
            "time_column": t_col,
            "scale": scale,
            "integer_times": bool(np.all(raw_t == np.round(raw_t))),
            "kept": {rest[j]: numbers[:, j] for j in kept},
        },
    }
    values[missing] = np.nan
    return Animation(times, values, tuple(rest[j] for j in chans), meta)


def _unit(t: np.ndarray) -> float:
    """Seconds per unit of a ``timestamp`` column, from its median positive step."""
    steps = np.diff(t)
    steps = steps[steps > 0]
    if not len(steps):
        return 1.0
    step = float(np.median(steps))
    return 1.0 if step < 0.5 else 1e-3 if step < 500 else 1e-6


def write(anim: Animation, f: BinaryIO) -> None:
    """The source's columns and time unit when it was a MediaPipe CSV, else ``timestamp_ms``."""
    mp = anim.meta.get("mediapipe") if anim.meta.get("format") == "mediapipe" else None
    n = anim.n_frames
    if mp is not None and len(next(iter(mp["kept"].values()), np.zeros(n))) == n:
        header, t_col, scale = list(mp["header"]), int(mp["time_column"]), float(mp["scale"])
        integer, kept = bool(mp["integer_times"]), mp["kept"]
    else:
        header, t_col, scale, integer, kept = ["timestamp_ms", *anim.names], 0, 1e-3, False, {}
    rest = [h for j, h in enumerate(header) if j != t_col]
    by_name = {name: anim.values[:, j] for j, name in enumerate(anim.names)}
    missing = set(rest) - set(by_name) - set(kept)
    if missing:
        raise FacecleanError(f"cannot write a MediaPipe CSV: no column {sorted(missing)[0]!r}")
    plain_csv.header_text(tuple(header))  # refuses a name a CSV cannot hold
    f.write((",".join(header) + "\n").encode("utf-8"))
    t = anim.times / scale
    cols = [kept[h] if h in kept else by_name[h] for h in rest]
    table = np.stack(cols, axis=1) if cols else np.zeros((n, 0))
    out = []
    for k in range(n):
        cells = ["" if v != v else repr(v) for v in table[k].tolist()]
        stamp = str(int(round(t[k]))) if integer else repr(float(t[k]))
        cells.insert(t_col, stamp)
        out.append(",".join(cells) + "\n")
    f.write("".join(out).encode("utf-8"))
