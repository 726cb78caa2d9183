"""The learned models' file formats, named once: checkpoints (.npz) and the ONNX step graph.

Every reader and writer (``learned/``, ``neural/``, ``evaluation/``) takes these strings
from here. A checkpoint's ``config`` (a 0-d JSON string) carries its ``format``.
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from faceclean import strict_json
from faceclean.errors import FacecleanError
from faceclean.io.npz_safe import MiB, load_arrays
from faceclean.io.source import open_binary, regular

LSTM = "faceclean-lstm/1"  # the recurrent cleaner (learned/checkpoint.py)
FC = "faceclean-fc/1"  # the fully connected baseline (learned/derivative_net.py)
GBT = "faceclean-gbt/1"  # the boosted-trees baseline (learned/derivative_net.py)
ADAPTIVE = "faceclean-adaptive/1"  # the learned adaptive One Euro (learned/adaptive.py)
TRACKER_MAP = "faceclean-tracker-map/1"  # a tracker's learned level map (learned/tracker_map.py)
STEP = "faceclean-lstm-step/1"  # ONNX metadata "faceclean.format" of an exported step graph
METHODS = {
    LSTM: "lstm",
    FC: "fc",
    GBT: "gbt",
    ADAPTIVE: "adaptive",
    TRACKER_MAP: "tracker-map",
}  # checkpoint format -> method name
MAX_MODEL_BYTES = 64 * MiB  # a bigger file (or one unpacking bigger) is refused


def model_file(path: str | os.PathLike) -> Path:
    """``path`` when it names a regular file (the bounded reader's check), else one line:
    "no such model file: m.npz", "m.npz: a FIFO, not a regular file"."""
    regular(path, "model file")
    return Path(path)


def read_arrays(path: str | os.PathLike) -> dict[str, Any]:
    """Every array of a checkpoint file by name (``config`` among them): the one reader
    of model files. Never unpickles; size-checked (``MAX_MODEL_BYTES``); one-line
    FacecleanError for a missing file or one that is not a readable .npz."""
    p = Path(path)
    with open_binary(p, "model file") as f:  # a regular file, else one true line
        if f.read(4) != b"PK\x03\x04":  # an .npz is a zip archive
            raise FacecleanError(f"{p.name}: not a model .npz (not a zip archive)")
    return load_arrays(p, MAX_MODEL_BYTES, "model .npz")


def read(path: str | os.PathLike) -> tuple[dict[str, Any], dict]:
    """(config, the other arrays) of a checkpoint (``read_arrays``); the config is only
    parsed here: each format's loader checks it."""
    p = Path(path)
    return split(read_arrays(p), p.name)


def split(arrays: dict[str, Any], label: str) -> tuple[dict[str, Any], dict]:
    """(config, the other arrays) of a checkpoint's arrays: the config parsed (strict
    JSON, an object), not yet checked."""
    arrays = dict(arrays)
    try:
        raw = str(arrays.pop("config")[()])
    except (KeyError, ValueError, TypeError, IndexError) as e:
        raise FacecleanError(f"{label}: no readable 'config' ({e})") from None
    config = strict_json.loads(raw, f"{label}: config", max_depth=strict_json.MAX_DEPTH)
    if not isinstance(config, dict):
        raise FacecleanError(f"{label}: 'config' is not a JSON object")
    if not isinstance(config.get("format", ""), str):  # every reader looks it up by name
        raise FacecleanError(f"{label}: the config's format is not a name")
    return config, arrays


def write(
    path: str | os.PathLike,
    config: dict[str, Any],
    arrays: dict[str, Any],
    check: Callable[[dict[str, np.ndarray]], object],
    *,
    compressed: bool = False,
) -> None:
    """Write a checkpoint only once it is known good, so that no model that its loader
    refuses, or that holds a NaN, is ever written (docs/ROBUSTNESS.md, class 13): every
    array finite; the config strict JSON (a non-finite fact, such as a score that could
    not be measured, is null); the bytes within what ``read_arrays`` accepts, and read
    back from memory as it reads a file, then given to ``check``, the format's own loader
    (it raises FacecleanError for what it would refuse). Then written atomically; else
    one line, ``m.npz: not written: <why>``, and nothing written."""
    name = Path(path).name
    for key, a in arrays.items():
        a = np.asarray(a)
        if a.dtype.kind in "fc" and not np.isfinite(a).all():
            n = int((~np.isfinite(a)).sum())
            raise FacecleanError(
                f"{name}: not written: array {key!r} holds {n} NaN or infinite numbers"
            )
    data = {**arrays, "config": np.array(strict_json.dumps(config))}
    buf = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buf, **data)
    blob = buf.getvalue()
    if len(blob) > MAX_MODEL_BYTES:
        raise FacecleanError(
            f"{name}: not written: over the {MAX_MODEL_BYTES // MiB} MiB a model may be"
        )
    try:
        with np.load(io.BytesIO(blob), allow_pickle=False) as z:
            back = {k: z[k] for k in z.files}
        if sum(a.nbytes for a in back.values()) > MAX_MODEL_BYTES:
            raise FacecleanError(f"unpacks to over {MAX_MODEL_BYTES // MiB} MiB")
        check(back)
    except FacecleanError as e:
        raise FacecleanError(f"{name}: not written: {e}") from None
    from faceclean.io.atomic import atomic_write

    atomic_write(path, blob)


def is_model_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` looks like a checkpoint: a regular .npz file (a zip) holding a
    ``config`` array and no animation arrays. Reads only the zip's directory."""
    import zipfile

    p = Path(path)
    try:
        if not p.is_file() or p.stat().st_size > MAX_MODEL_BYTES:
            return False
        with zipfile.ZipFile(p) as z:
            names = set(z.namelist())
    except (OSError, zipfile.BadZipFile, ValueError):
        return False
    return "config.npy" in names and "values.npy" not in names


def method_of(path: str | os.PathLike) -> str:
    """The method ("lstm", "fc", "gbt") a checkpoint file is for, from its format."""
    config, _ = read(path)
    fmt = config.get("format")
    if fmt not in METHODS:
        known = ", ".join(METHODS)
        raise FacecleanError(f"{Path(path).name}: format {fmt!r} is not a model ({known})")
    return METHODS[fmt]
