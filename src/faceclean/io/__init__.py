"""Readers and writers, all to and from :class:`~faceclean.animation.Animation`.

Each format module has ``read(path) -> Animation`` and ``write(animation, file)``
(``file`` a binary file object) and ``sniff(head: bytes) -> bool``. The format is chosen
by extension, or by content when the extension is ambiguous (``.csv``).
"""

from __future__ import annotations

import importlib
import os
import struct
import zipfile
from pathlib import Path
from types import ModuleType

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import repeated
from faceclean.errors import FacecleanError
from faceclean.io import paths, source  # noqa: F401 (io.paths: the output policy)
from faceclean.io.atomic import atomic_open, writable

# format name -> module; extensions that select it.
FORMATS: dict[str, str] = {
    "livelink": "faceclean.io.livelink_csv",
    "mediapipe": "faceclean.io.mediapipe_csv",
    "csv": "faceclean.io.plain_csv",
    "json": "faceclean.io.json_format",
    "npz": "faceclean.io.npz_format",
    "gltf": "faceclean.io.gltf",
}
# What a reader raises on a malformed file (anything else is a bug the fuzzer must find).
_BAD_INPUT = (
    ValueError,
    KeyError,
    IndexError,
    TypeError,
    UnicodeDecodeError,
    OSError,
    EOFError,
    RecursionError,
    OverflowError,
    zipfile.BadZipFile,
    struct.error,
)
EXTENSIONS: dict[str, tuple[str, ...]] = {
    ".csv": ("livelink", "mediapipe", "csv"),
    ".json": ("json",),
    ".npz": ("npz",),
    ".gltf": ("gltf",),
    ".glb": ("gltf",),
}


def _module(fmt: str) -> ModuleType:
    if fmt not in FORMATS:
        raise FacecleanError(f"unknown format {fmt!r} (known: {', '.join(FORMATS)})")
    return importlib.import_module(FORMATS[fmt])


def detect(path: str | os.PathLike) -> str:
    """The format name of an existing file, by extension, then content."""
    p = Path(path)
    candidates = EXTENSIONS.get(p.suffix.lower())
    if candidates is None:
        raise FacecleanError(
            f"{p.name}: unknown file type {p.suffix or '(none)'!r} "
            f"(known: {', '.join(sorted(EXTENSIONS))})"
        )
    if len(candidates) == 1:
        return candidates[0]
    with source.open_binary(p) as f:
        head = f.read(4096)
    for fmt in candidates:
        if _module(fmt).sniff(head):
            return fmt
    raise FacecleanError(
        f"{p.name}: not a Live Link Face CSV, a MediaPipe CSV (timestamp_ms) "
        "nor a plain CSV with a 'time' column"
    )


def load(path: str | os.PathLike, fmt: str | None = None) -> Animation:
    """Read an animation file; raises FacecleanError with a one-line reason on bad input."""
    p = Path(path)
    source.regular(p)  # no FIFO, device or folder: nothing blocks, nothing reads forever
    fmt = fmt or detect(p)
    try:
        anim = _module(fmt).read(p)
    except FacecleanError:
        raise
    except _BAD_INPUT as e:
        raise FacecleanError(f"{p.name}: not a readable {fmt} file ({_short(e)})") from None
    anim.meta.setdefault("format", fmt)
    return checked(anim, p.name)


def checked(anim: Animation, label: str) -> Animation:
    """``anim`` if it holds the invariants every reader promises, else FacecleanError.

    At least one frame; times (N,) finite seconds (order is not checked: cleaners hold
    on a repeated or backwards time); values (N, M) float64; M string names.
    """
    if anim.n_frames == 0:
        raise FacecleanError(f"{label}: no frames")
    if anim.n_channels == 0:
        raise FacecleanError(f"{label}: no channels")
    bad = np.flatnonzero(~np.isfinite(anim.times))
    if len(bad):
        raise FacecleanError(f"{label}: frame {bad[0]} has no finite time")
    if anim.values.dtype != np.float64 or anim.values.ndim != 2:
        raise FacecleanError(f"{label}: values are not a (frames, channels) table")
    if (twice := repeated(anim.names)) is not None:  # every command matches by channel
        raise FacecleanError(f"{label}: channel {twice!r} is given twice: name each once")
    pose, pose_names = anim.meta.get("pose"), tuple(anim.meta.get("pose_names", ()))
    if pose is not None:  # passthrough columns: (N, P), one name per column
        shape = np.shape(pose)
        if len(shape) != 2 or shape[0] != anim.n_frames or shape[1] != len(pose_names):
            raise FacecleanError(
                f"{label}: 'pose' is {shape}, expected {anim.n_frames} rows x "
                f"{len(pose_names)} (one column per pose name)"
            )
    start = anim.meta.get("timecode_start")
    if start is not None and not 0.0 <= start < 86400.0:  # NaN compares False
        raise FacecleanError(f"{label}: timecode_start {start!r} is not a time of day in s")
    for n in (*anim.names, *pose_names):
        if not isinstance(n, str):
            raise FacecleanError(f"{label}: channel names must be text")
        try:
            n.encode("utf-8")
        except UnicodeEncodeError:  # a lone surrogate (JSON "\ud800", a numpy str)
            raise FacecleanError(f"{label}: channel name {n!r} is not valid Unicode") from None
    return anim


def _short(e: BaseException) -> str:
    """A one-line reason for an exception (first line, at most 200 characters)."""
    text = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
    return text[:200]


def output_format(path: str | os.PathLike, source: str | None, fmt: str | None = None) -> str:
    """The format a write to ``path`` uses: ``fmt``, else by extension, the ``source``
    format when the extension allows it (a Live Link take to ``.csv`` stays Live Link)."""
    p = Path(path)
    candidates = EXTENSIONS.get(p.suffix.lower())
    if fmt is not None:  # a name that says another format: no reader would take it back
        if candidates is None or fmt not in candidates:
            fits = " or ".join(e for e, c in EXTENSIONS.items() if fmt in c) or "its own"
            raise FacecleanError(f"--format {fmt} writes a {fits} file, not {p.name}: name "
                                 "the output so")  # fmt: skip
        return fmt
    if candidates is None:
        ext, known = p.suffix or "(no extension)", ", ".join(sorted(EXTENSIONS))
        raise FacecleanError(f"{os.fspath(path)}: unknown output type {ext!r}: name a file "
                             f"ending {known}")  # fmt: skip
    return source if source in candidates else candidates[-1]


def check_output(
    path: str | os.PathLike, fmt: str | None = None, source: str | None = None
) -> None:
    """Refuse now what ``save(.., path)`` would refuse for its path (missing folder, a
    folder, a FIFO or device, an input of this command, an unknown type): a command with
    several outputs checks them all before writing the first."""
    writable(path)
    _module(output_format(Path(path), source, fmt))


def save_options(
    path: str | os.PathLike, source: str | None, fmt: str | None, compress: bool = False
) -> dict[str, bool]:
    """The writer's keywords for these options; ``compress`` on a format that cannot
    (only npz deflates) is one line."""
    if not compress:
        return {}
    name = output_format(Path(path), source, fmt)
    if not getattr(_module(name), "COMPRESSES", False):
        raise FacecleanError(f"{Path(path).name}: --compress is for npz output, not {name}")
    return {"compress": True}


def save(
    anim: Animation, path: str | os.PathLike, fmt: str | None = None, compress: bool = False
) -> None:
    """Write atomically; the format comes from ``fmt``, the extension, or the source format.
    ``compress``: deflate what the format can (npz); a format that cannot is refused."""
    p = Path(path)
    module = _module(output_format(p, anim.meta.get("format"), fmt))
    extra = save_options(p, anim.meta.get("format"), fmt, compress)
    with atomic_open(path, "wb") as f:  # the name as given: "out.csv/" is refused
        if getattr(module, "WRITE_NEEDS_PATH", False):  # glTF: .glb or .gltf by the name
            module.write(anim, f, path=p)
        else:
            module.write(anim, f, **extra)
