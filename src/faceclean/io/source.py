"""The one bounded reader: every file faceclean reads goes through here first.

An input must be a regular file (a symlink is followed): a FIFO, a device (``/dev/zero``),
a socket or a folder is refused before it is opened, so nothing blocks on a FIFO without
a writer and nothing reads without end. What is read is bounded, so memory stays in
proportion to the input whatever its content:

- a file read whole: at most ``MAX_FILE`` bytes (a Live Link or plain CSV cleaned by a
  causal cleaner streams instead and has no size bound);
- a CSV data cell (Live Link or plain) longer than ``MAX_CELL`` bytes is parsed on its
  own (it must be a number) and stands in the cell table as its shortest repr, so the
  fixed-width table costs at most ~8x the float64 values whatever one cell holds (the
  line's text, written back, keeps the cell as it was); a header cell is at most
  ``MAX_NAME`` bytes, a row at most ``MAX_FIELDS`` fields;
- an npz animation unpacks to at most ``MAX_UNPACKED`` bytes (model files: 64 MiB,
  ``npz_safe``); a glTF ``data:`` URI decodes to at most ``MAX_FILE`` bytes.

Each refusal is one line naming the file and the bound, and says what the file is
(``what``: "no such calibration file: c.json", "p.json: a FIFO, not a regular file").

The API every reader uses (a new file type, e.g. a pairs shard or a tracker model,
takes the same path; nothing opens a user's file any other way):

- ``regular(path, what)``: the stat of a regular file, else one line; notes the input
  (``io.paths``: no output of this command may replace it);
- ``open_binary(path, what)``: a file object, once ``regular`` accepts the path;
- ``read_bytes(path, limit, what)``: the whole file, at most ``limit`` bytes;
- ``read_text(path, what, limit=MAX_DOC)``: the whole file as UTF-8 text;
- ``read_json(path, what, limit=MAX_DOC, max_depth=MAX_DEPTH)``: a document in strict
  JSON (``strict_json``: finite numbers, bounded nesting);
- ``named(path)``: whether a path names something that exists (a dangling link too), so
  a caller that falls back to a shipped name lets ``regular`` say what is wrong instead;
- ``check_times(times, label, increasing, limit)``: a time column's rows finite (and, for
  a format whose times must, increasing and within a bound), else one line naming the row.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from faceclean import strict_json
from faceclean.errors import FacecleanError
from faceclean.io import paths
from faceclean.io.paths import kind

MiB = 1 << 20
MAX_FILE = 1024 * MiB  # bytes of a file read whole
MAX_DOC = 16 * MiB  # bytes of a settings document (calibration, levels, preset, pairs)
MAX_DEPTH = strict_json.MAX_DEPTH  # nesting of a settings document
MAX_UNPACKED = 512 * MiB  # bytes an npz animation may unpack to
MAX_CELL = 64  # bytes of one CSV data cell (a number needs at most ~25)
MAX_NAME = 256  # bytes of one CSV header cell (a channel name)
MAX_FIELDS = 4096  # fields of one CSV row
MAX_LINE = (MAX_NAME + 1) * MAX_FIELDS  # bytes of one CSV line
BOM = b"\xef\xbb\xbf"  # UTF-8 byte order mark some tools write before a CSV header


def regular(path: str | os.PathLike, what: str = "file") -> os.stat_result:
    """The stat of ``path`` when it is a regular file (symlinks followed), else one line."""
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise FacecleanError(f"no such {what}: {p}") from None
    except OSError as e:
        raise FacecleanError(f"cannot read {p}: {e.strerror or e}") from None
    except ValueError:  # a NUL byte in the name (argv has none; a JSON string may)
        raise FacecleanError(f"no such {what}: {os.fspath(path)!r}") from None
    if stat.S_ISDIR(st.st_mode):
        raise FacecleanError(f"is a folder, not a file: {p}")
    if not stat.S_ISREG(st.st_mode):
        raise FacecleanError(f"{p}: {kind(st.st_mode)}, not a regular file")
    if paths.kernel(p, st):  # /proc/self/mem stats as a regular file of 0 bytes
        raise FacecleanError(f"{p}: a kernel file (/proc, /sys), not a regular file")
    paths.note_input(st)  # a command never overwrites what it reads (io.paths)
    return st


def open_binary(path: str | os.PathLike, what: str = "file") -> BinaryIO:
    """``path`` opened for reading, once ``regular`` accepts it."""
    regular(path, what)
    try:
        return open(path, "rb")  # noqa: SIM115 (the caller closes it)
    except OSError as e:
        raise FacecleanError(f"cannot read {path}: {e.strerror or e}") from None


def read_bytes(path: str | os.PathLike, limit: int = MAX_FILE, what: str = "file") -> bytes:
    """The whole of a regular file, at most ``limit`` bytes (a larger one is refused)."""
    p = Path(path)
    size = regular(p, what).st_size
    if size > limit:
        raise FacecleanError(f"{p.name}: {size_text(size)}, over the {size_text(limit)} limit")
    parts, total = [], 0
    with open_binary(p, what) as f:  # the stat size first, then on while it grows
        try:
            while total <= limit and (part := f.read(min(size, limit) + 1 if not parts else MiB)):
                parts.append(part)
                total += len(part)
        except OSError as e:  # a disk error, a file that fails mid-read: one line
            raise FacecleanError(f"cannot read {p}: {e.strerror or e}") from None
    if total > limit:
        raise FacecleanError(f"{p.name}: over the {size_text(limit)} limit")
    return b"".join(parts) if len(parts) != 1 else parts[0]


def read_text(path: str | os.PathLike, what: str = "file", limit: int = MAX_DOC) -> str:
    """The whole of a regular UTF-8 text file (a leading BOM dropped), at most ``limit``."""
    data = read_bytes(path, limit, what).removeprefix(BOM)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise FacecleanError(f"{Path(path).name}: not UTF-8 text (byte {e.start})") from None


def read_json(
    path: str | os.PathLike,
    what: str = "file",
    limit: int = MAX_DOC,
    *,
    max_depth: int | None = MAX_DEPTH,
    numbers: bool = True,
) -> Any:
    """A strict JSON document (UTF-8, RFC 8259) from a regular file of at most ``limit``
    bytes, nested at most ``max_depth`` deep (None: the parser's own bound)."""
    p = Path(path)
    try:
        text = read_bytes(p, limit, what).removeprefix(BOM).decode("utf-8")
    except UnicodeDecodeError as e:
        raise FacecleanError(f"{p.name}: not valid JSON (not UTF-8: byte {e.start})") from None
    return strict_json.loads(text, p.name, numbers=numbers, max_depth=max_depth)


def named(path: str | os.PathLike) -> bool:
    """Whether ``path`` names an existing entry (a dangling symlink counts): the user
    meant that file, and ``regular`` will say what is wrong with it."""
    try:
        return os.path.lexists(path)
    except (OSError, ValueError):  # a NUL byte
        return False


def check_cells(fields: list[bytes], label: str, limit: int = MAX_CELL) -> None:
    """Refuse a CSV row with a field over ``limit`` bytes or more than MAX_FIELDS fields."""
    if len(fields) > MAX_FIELDS:
        raise FacecleanError(f"{label}: {len(fields)} fields (at most {MAX_FIELDS})")
    if max(map(len, fields), default=0) > limit:
        raise FacecleanError(f"{label}: a cell longer than {limit} bytes")


def check_times(
    times: np.ndarray,
    label: str,
    *,
    increasing: bool = False,
    limit: float = np.inf,
    first: int = 0,
) -> None:
    """Refuse a time column (R,) s with a row that is not finite, beyond +-``limit`` s, or
    (``increasing``) not later than the row before. The message names the row, counted
    from 1 after the ``first`` rows read before these."""
    bad = np.flatnonzero(~np.isfinite(times) | (np.abs(times) > limit))
    if len(bad):
        k = int(bad[0])
        if not np.isfinite(times[k]):
            raise FacecleanError(f"{label}: row {first + k + 1} has no finite time")
        raise FacecleanError(
            f"{label}: row {first + k + 1}: time {times[k]:.6g} s is beyond the +-{limit:.3g} s "
            "a timestamp of this format can hold"
        )
    if increasing:
        back = np.flatnonzero(np.diff(times) <= 0.0)
        if len(back):
            k = int(back[0]) + 1
            raise FacecleanError(
                f"{label}: row {first + k + 1}: time {times[k]:.6g} s is not after the row before "
                f"({times[k - 1]:.6g} s); this format's times increase (sort the rows, drop "
                "repeated ones)"
            )


def short_cells(fields: list[bytes], label: str) -> list[bytes]:
    """A CSV row's data cells with every cell over MAX_CELL bytes replaced by the shortest
    text of the same float64 (a long cell that is not a number is refused)."""
    if len(fields) > MAX_FIELDS:
        raise FacecleanError(f"{label}: {len(fields)} fields (at most {MAX_FIELDS})")
    if max(map(len, fields), default=0) <= MAX_CELL:
        return fields
    out = []
    for cell in fields:
        if len(cell) > MAX_CELL:
            try:
                cell = repr(float(cell)).encode()
            except ValueError:
                text = cell[:20].decode("utf-8", "replace")
                raise FacecleanError(f"{label}: a value is not a number ({text!r}...)") from None
        out.append(cell)
    return out


def size_text(n: int) -> str:
    return f"{n / MiB:.1f} MiB" if n >= MiB // 10 else f"{n} bytes"


CHUNK = 1 << 20  # bytes per read of a text file streamed line by line


def iter_lines(f: BinaryIO, chunk: int | None = None) -> Iterator[bytes]:
    """The lines of a binary file with their endings, exactly as
    ``f.read().splitlines(keepends=True)`` gives them, reading ``chunk`` bytes at a time."""
    buf, chunk = b"", chunk or CHUNK  # (CHUNK read now: a test may set it)
    while data := f.read(chunk):
        lines = (buf + data).splitlines(keepends=True)
        buf = b"" if lines[-1].endswith(b"\n") else lines.pop()  # "\r" may precede "\n"
        if len(buf) > MAX_LINE:
            raise FacecleanError(f"a line longer than {MAX_LINE} bytes: not a CSV file")
        yield from lines
    if buf:
        yield from buf.splitlines(keepends=True)
