"""Reading ``.npz`` archives safely: never unpickle, check sizes before reading.

Every npz the project reads (animations, model checkpoints) is untrusted input. numpy
with ``allow_pickle=False`` refuses object arrays and pickles; around it this module
refuses what numpy would raise something else for (a zip that is not an npz, a
truncated file, an unsupported compression method) and what would cost too much
memory (a file, or an archive that unpacks, beyond ``max_bytes``: a zip bomb).
"""

from __future__ import annotations

import os
import struct
import zipfile
from pathlib import Path

import numpy as np

from faceclean.errors import FacecleanError
from faceclean.io.source import regular

MiB = 1 << 20
_FAILURES = (
    zipfile.BadZipFile,
    ValueError,  # pickled or object arrays, bad .npy headers
    OSError,
    EOFError,
    KeyError,
    NotImplementedError,  # compression methods zipfile lacks
    struct.error,
    RuntimeError,  # encrypted members
)


def load_arrays(
    path: str | os.PathLike, max_bytes: int | None = None, what: str = "npz file"
) -> dict[str, np.ndarray]:
    """Every array of an .npz by name; FacecleanError (one line) for anything else.

    ``max_bytes``: refuse a file larger than this, or one whose arrays unpack larger.
    """
    p = Path(path)
    size = regular(p, what).st_size  # no FIFO, device or folder
    if max_bytes is not None and size > max_bytes:
        raise FacecleanError(f"{p.name}: {_size(size)}, over the {_size(max_bytes)} limit")
    try:
        with zipfile.ZipFile(p) as z:
            members = z.infolist()
            unpacked = sum(m.file_size for m in members)
            if max_bytes is not None and unpacked > max_bytes:
                raise FacecleanError(
                    f"{p.name}: unpacks to {_size(unpacked)}, over the {_size(max_bytes)} limit"
                )
            bad = [m.filename for m in members if not m.filename.endswith(".npy")]
            if bad:
                raise FacecleanError(f"{p.name}: not an npz archive (holds {bad[0][:60]!r})")
        with np.load(p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except _FAILURES as e:
        text = " ".join(str(e).split())[:200] or type(e).__name__
        raise FacecleanError(f"{p.name}: not a readable {what} ({text})") from None


def _size(n: int) -> str:
    return f"{n / MiB:.1f} MiB" if n >= MiB // 10 else f"{n} bytes"
