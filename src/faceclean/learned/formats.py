"""The learned models' file formats, named once: checkpoints (.npz) and the ONNX step graph.

Every reader and writer (``learned/``, ``neural/``, ``evaluation/``) takes these strings
from here. A checkpoint's ``config`` (a 0-d JSON string) carries its ``format``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

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
    arrays = read_arrays(p)
    try:
        raw = str(arrays.pop("config")[()])
    except (KeyError, ValueError, TypeError, IndexError) as e:
        raise FacecleanError(f"{p.name}: no readable 'config' ({e})") from None
    config = strict_json.loads(raw, f"{p.name}: config", max_depth=strict_json.MAX_DEPTH)
    if not isinstance(config, dict):
        raise FacecleanError(f"{p.name}: 'config' is not a JSON object")
    return config, arrays


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
