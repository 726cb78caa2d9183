"""Where things are: the shared data folder and the shipped files."""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
MODELS = PACKAGE / "models"
PRESETS = PACKAGE / "presets"


def data_dir() -> Path | None:
    """The data folder: $FACECLEAN_DATA, else ../shared/data beside the repository or cwd."""
    env = os.environ.get("FACECLEAN_DATA")
    if env:
        return Path(env)
    for base in (PACKAGE.parents[1], Path.cwd()):  # the repository root (src layout), cwd
        candidate = base.parent / "shared" / "data"
        if candidate.is_dir():
            return candidate
    return None


def takes_dir() -> Path | None:
    """The clean ARKit takes (``data_dir()/arkit_takes``), or None when absent."""
    d = data_dir()
    return d / "arkit_takes" if d is not None and (d / "arkit_takes").is_dir() else None


def mesh_file(name: str) -> Path | None:
    """A shared face mesh (``data_dir()/meshes/NAME``), or None when absent."""
    d = data_dir()
    return d / "meshes" / name if d is not None else None


def tracker_model() -> Path | None:
    """MediaPipe's Face Landmarker bundle: $FACECLEAN_TRACKER_MODEL, else
    ``../shared/models/face_landmarker.task`` beside the data folder (never downloaded)."""
    env = os.environ.get("FACECLEAN_TRACKER_MODEL")
    if env:
        return Path(env)
    d = data_dir()
    return d.parent / "models" / "face_landmarker.task" if d is not None else None
