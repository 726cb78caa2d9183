"""Reading ``.npz`` archives safely: never unpickle, check sizes before reading.

Every npz the project reads (animations, model checkpoints) is untrusted input. numpy
with ``allow_pickle=False`` refuses object arrays and pickles; around it this module
refuses what numpy would raise something else for (a zip that is not an npz, a
truncated file, an unsupported compression method) and what would cost too much
memory (a file, or an archive that unpacks, beyond ``max_bytes``: a zip bomb; an array
whose ``.npy`` header claims more than its member holds, which numpy would allocate
before reading a byte of it).
"""

from __future__ import annotations

import math
import os
import struct
import zipfile
import zlib
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
    zlib.error,  # a corrupt deflated member
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
            for m in members:
                _check_header(z, m, p.name)
        with np.load(p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except _FAILURES as e:
        text = " ".join(str(e).split())[:200] or type(e).__name__
        raise FacecleanError(f"{p.name}: not a readable {what} ({text})") from None


def _check_header(z: zipfile.ZipFile, m: zipfile.ZipInfo, label: str) -> None:
    """Refuse a member whose ``.npy`` header claims more bytes than the member holds
    (numpy allocates the claimed shape before reading)."""
    fmt = np.lib.format
    with z.open(m) as f:
        version = fmt.read_magic(f)
        if version == (1, 0):
            shape, _, dtype = fmt.read_array_header_1_0(f)
        elif version == (2, 0):
            shape, _, dtype = fmt.read_array_header_2_0(f)
        else:
            raise ValueError(f"{m.filename}: .npy format {version[0]}.{version[1]}")
        held = m.file_size - f.tell()  # bytes of array data in the member
    if dtype.hasobject:
        return  # a pickle: np.load(allow_pickle=False) refuses it unread, in its own words
    claimed = math.prod(shape) * max(dtype.itemsize, 1)  # B; Python ints: no overflow
    if claimed > held:
        raise FacecleanError(
            f"{label}: {m.filename[:60]} claims {shape} {dtype} ({_size(claimed)}) but holds "
            f"{_size(max(held, 0))} (truncated or forged)"
        )


def _size(n: int) -> str:
    return f"{n / MiB:.1f} MiB" if n >= MiB // 10 else f"{n} bytes"
