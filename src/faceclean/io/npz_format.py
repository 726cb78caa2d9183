"""NumPy ``.npz`` animation files (loaded with ``allow_pickle=False``).

Written uncompressed (``io.save(.., compress=True)``, ``clean --compress``: deflated);
read either way. Keys: ``format`` (0-d str ``faceclean-animation/1``), ``times`` (N,) float64 s,
``values`` (N, M) float64 with NaN for missing, ``names`` (M,) str; optional
passthrough ``pose`` (N, P), ``pose_names`` (P,), ``timecode_start`` (0-d, s of the day).
On read, ``time`` and ``weights`` are accepted for ``times`` and ``values`` (the layout of
``raw_streams/llv_dao.npz``) and ``format`` may be absent.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.io.npz_safe import load_arrays
from faceclean.io.source import MAX_UNPACKED

FORMAT = "faceclean-animation/1"


def sniff(head: bytes) -> bool:
    return head.startswith(b"PK\x03\x04")


def read(path: str | os.PathLike) -> Animation:
    """Read an ``.npz`` animation."""
    p = Path(path)
    arrays = load_arrays(p, MAX_UNPACKED)
    if "format" in arrays and str(arrays["format"]) != FORMAT:
        raise FacecleanError(f"{p.name}: format {str(arrays['format'])!r}, expected {FORMAT!r}")
    times = arrays.get("times", arrays.get("time"))
    values = arrays.get("values", arrays.get("weights"))
    names = arrays.get("names")
    if times is None or values is None or names is None:
        raise FacecleanError(f"{p.name}: needs 'times', 'values' and 'names' arrays")
    if np.ndim(times) != 1 or np.ndim(names) != 1 or names.dtype.kind not in "US":
        raise FacecleanError(f"{p.name}: 'times' and 'names' must be 1-D (names as text)")
    times, values = _real(times, "times", p.name), _real(values, "values", p.name)
    if values.ndim != 2 or values.shape != (len(times), len(names)):
        raise FacecleanError(
            f"{p.name}: 'values' is {values.shape}, expected {len(times)} x {len(names)}"
        )
    meta: dict[str, Any] = {"format": "npz"}
    if "pose" in arrays:
        pose = _real(arrays["pose"], "pose", p.name)
        pose_names = _text(arrays.get("pose_names", np.zeros(0, "U1")), "pose_names", p.name)
        if pose.ndim != 2 or len(pose) != len(times) or pose.shape[1] != len(pose_names):
            raise FacecleanError(
                f"{p.name}: 'pose' is {pose.shape}, expected {len(times)} x "
                f"{len(pose_names)} (one column per pose name)"
            )
        meta["pose"], meta["pose_names"] = pose, pose_names
    if "timecode_start" in arrays:
        start = _real(arrays["timecode_start"], "timecode_start", p.name)
        if start.ndim != 0 or not np.isfinite(start):
            raise FacecleanError(f"{p.name}: 'timecode_start' must be one finite number")
        meta["timecode_start"] = float(start)
    return Animation(times, values, _text(names, "names", p.name), meta)


def _real(a: np.ndarray, key: str, label: str) -> np.ndarray:
    """A numeric array as float64; complex, text and other kinds are refused."""
    if a.dtype.kind not in "biuf":
        raise FacecleanError(f"{label}: '{key}' holds {a.dtype} values, not real numbers")
    return a.astype(np.float64, copy=False)  # float64 already (ours): the array as read


def _text(a: np.ndarray, key: str, label: str) -> tuple[str, ...]:
    """A 1-D str or bytes (UTF-8) array as a tuple of str."""
    if a.ndim != 1 or a.dtype.kind not in "US":
        raise FacecleanError(f"{label}: '{key}' must be a 1-D array of text")
    try:
        return tuple(n.decode("utf-8") if isinstance(n, bytes) else str(n) for n in a.tolist())
    except UnicodeDecodeError:
        raise FacecleanError(f"{label}: '{key}' is not UTF-8 text") from None


COMPRESSES = True  # io.save(.., compress=True): zip's deflate, asked for (issue 38)


def write(anim: Animation, f: BinaryIO, compress: bool = False) -> None:
    """Write the keys above (float64), uncompressed unless ``compress``: a take's float64
    noise hardly deflates (an hour at 60 fps: 91.6 MB in, 91.6 MB out, 4.5 s of zlib)."""
    arrays: dict[str, np.ndarray] = {
        "format": np.array(FORMAT),
        "times": anim.times,
        "values": anim.values,
        "names": np.array(anim.names, dtype=str),
    }
    pose = np.asarray(anim.meta.get("pose", np.zeros((0, 0))), dtype=np.float64)
    if pose.ndim == 2 and pose.shape[0] == anim.n_frames and pose.shape[1]:
        arrays["pose"] = pose
        arrays["pose_names"] = np.array(anim.meta.get("pose_names", ()), dtype=str)
    if "timecode_start" in anim.meta:
        arrays["timecode_start"] = np.array(float(anim.meta["timecode_start"]))
    (np.savez_compressed if compress else np.savez)(f, **arrays)
