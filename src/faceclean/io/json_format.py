"""JSON animation files (layout ``faceclean-animation/1``).

::

    {"format": "faceclean-animation/1",
     "channels": ["eyeBlinkLeft", ...],          # M names
     "times": [0.0, 0.0167, ...],                 # N, seconds
     "values": [[0.01, ...], ...],                # N rows of M numbers, null = missing
     "pose_names": [...], "pose": [[...], ...],   # optional passthrough (N rows)
     "timecode_start": 53882.7}                   # optional, s of the day

Numbers are written by Python's ``json`` (shortest repr, exact on read). A missing frame
is a row of nulls (a bare ``null`` row is read the same way). Infinite values are refused.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from faceclean import strict_json
from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.io import source

FORMAT = "faceclean-animation/1"


def sniff(head: bytes) -> bool:
    return head.lstrip().startswith(b"{")


def read(path: str | os.PathLike) -> Animation:
    """Read a ``faceclean-animation/1`` JSON file."""
    p = Path(path)
    doc = strict_json.loads(source.read_bytes(p), p.name, numbers=False)  # depth bounded
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise FacecleanError(f"{p.name}: not a {FORMAT} JSON file (see docs/FORMATS.md)")
    names = doc.get("channels")
    times = np.array(doc.get("times"), dtype=np.float64)
    m = len(names) if isinstance(names, list) else 0
    rows = doc.get("values")
    if not isinstance(names, list) or not isinstance(rows, list) or times.ndim != 1:
        raise FacecleanError(f"{p.name}: needs 'channels', 'times' and 'values' lists")
    if not all(isinstance(n, str) for n in names):
        raise FacecleanError(f"{p.name}: 'channels' must be a list of strings")
    values = np.array([[None] * m if r is None else r for r in rows], dtype=np.float64)
    values = values.reshape(len(rows), m) if values.size == 0 else values
    if values.shape != (len(times), m):
        raise FacecleanError(
            f"{p.name}: 'values' is {values.shape}, expected {len(times)} x {m} channels"
        )
    meta: dict[str, Any] = {"format": "json"}
    if "pose" in doc:
        meta["pose"] = np.array(doc["pose"], dtype=np.float64)
        meta["pose_names"] = tuple(doc.get("pose_names", ()))
    if "timecode_start" in doc:
        start = doc["timecode_start"]
        if isinstance(start, bool) or not isinstance(start, int | float):
            raise FacecleanError(f"{p.name}: 'timecode_start' must be a number")
        meta["timecode_start"] = float(start)
    return Animation(times, values, tuple(str(n) for n in names), meta)


def write(anim: Animation, f: BinaryIO) -> None:
    """Write the layout above, one frame per line. Strict JSON only: NaN is null (a
    missing value); an infinite value (weights, ``pose`` angles, times) has no JSON
    spelling and is refused in one line naming where it is, before anything is written."""
    head = {"format": FORMAT, "channels": list(anim.names), "times": anim.times.tolist()}
    extra: dict[str, Any] = {}
    pose = np.asarray(anim.meta.get("pose", np.zeros((0, 0))), dtype=np.float64)
    pose_names = list(anim.meta.get("pose_names", ()))
    has_pose = pose.ndim == 2 and pose.shape[0] == anim.n_frames and pose.shape[1] > 0
    refuse_infinite(anim.values, list(anim.names), "channel")
    if has_pose:
        refuse_infinite(pose, pose_names, "pose column")
        extra["pose_names"] = pose_names
        extra["pose"] = _rows(pose)
    if not np.isfinite(anim.times).all():
        k = int(np.flatnonzero(~np.isfinite(anim.times))[0])
        raise FacecleanError(f"JSON cannot hold a non-finite time (frame {k + 1})")
    if "timecode_start" in anim.meta:
        extra["timecode_start"] = float(anim.meta["timecode_start"])

    def dumps(v: Any) -> str:  # no NaN or Infinity token, ever: a strict reader reads it
        try:
            return json.dumps(v, allow_nan=False)
        except ValueError:
            raise FacecleanError("JSON cannot hold a non-finite number (timecode_start)") from None

    parts = [dumps(head)[:-1], ',\n "values": [']
    parts.append(",".join("\n  " + dumps(r) for r in _rows(anim.values)))
    parts.append("\n ]")
    for k, v in extra.items():
        parts.append(f",\n {dumps(k)}: {dumps(v)}")
    parts.append("\n}\n")
    f.write("".join(parts).encode("utf-8"))


def refuse_infinite(a: np.ndarray, names: list[str], what: str, fmt: str = "JSON") -> None:
    """FacecleanError naming the first infinite cell of ``a`` (N, M), if any: ``fmt``, a
    format with no spelling for one (JSON; Live Link CSV, whose readers take numbers)."""
    bad = np.argwhere(np.isinf(a))
    if len(bad):
        row, col = (int(v) for v in bad[0])
        name = names[col] if col < len(names) else str(col)
        raise FacecleanError(
            f"{fmt} cannot hold infinite values: {what} {name!r} is {a[row, col]:+g} at frame "
            f"{row + 1} ({len(bad)} such cells); write another format (CSV, NPZ) or fix them"
        )


def _rows(a: np.ndarray) -> list[list[float | None]]:
    """(N, M) -> nested lists with None for NaN."""
    return [[None if v != v else v for v in row] for row in a.tolist()]  # v != v: NaN
