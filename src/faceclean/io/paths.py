"""The one output-path policy: what a path named for writing may replace.

Every output goes through ``io.atomic`` (a temporary file beside the target, then a
rename), and ``atomic`` asks ``target`` here first:

- an existing output must be a regular file: a FIFO, a device (``-o /dev/null``), a
  socket or a folder is refused, never replaced by a regular file; a symlink is followed
  (its target is written, the link stays);
- inside a command (``command()``, entered by the CLI), every file the command read
  (``io.source`` notes them) is protected: an output naming one is refused (``tune -o``
  naming the truth, ``corrupt --truth-out`` naming the input), unless the command declared
  it rewritable (``clean IN -o IN --in-place``: the in-place clean the user asked for);
- two outputs of one command never name the same file (``distinct``).

Refusals are one line; nothing is created or changed.
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Iterator
from pathlib import Path

from faceclean.errors import FacecleanError


class _Command:
    def __init__(self) -> None:
        self.read: set[tuple[int, int]] = set()  # (st_dev, st_ino) of files read
        self.own: set[tuple[int, int]] = set()  # declared rewritable, or written by it


_current: _Command | None = None


@contextlib.contextmanager
def command() -> Iterator[None]:
    """The scope of one command: inputs read inside it are protected from its outputs."""
    global _current
    outer, _current = _current, _Command()
    try:
        yield
    finally:
        _current = outer


def note_input(st: os.stat_result) -> None:
    """Record a file the current command read (io.source calls this)."""
    if _current is not None:
        _current.read.add((st.st_dev, st.st_ino))


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether paths a and b name one existing file (``./``, symlinks, hard links)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # either one missing: not the same file
        return False


def verb(out: str | os.PathLike) -> str:
    """How a command says it wrote ``out``, asked before it writes: "replaced" where a file
    is there now (a file written over is said, never in silence), else "wrote"."""
    return "replaced" if os.path.isfile(out) else "wrote"


def onto_input(src: str | os.PathLike, out: str | os.PathLike, in_place: bool, rule: str) -> None:
    """An output that is its command's input (``same_file``): refused, saying ``rule``,
    unless ``in_place``; with it, declared rewritable. A raw take is never replaced
    unasked (``clean``, ``convert``)."""
    if not same_file(src, out):
        return
    if not in_place:
        raise FacecleanError(
            f"-o {out} is the input {src}: {rule}; name another file, or add --in-place to "
            "replace it"
        )
    rewritable(src)  # replaced atomically, once complete


def rewritable(path: str | os.PathLike) -> None:
    """Let the current command replace this input (an in-place clean or convert)."""
    if _current is not None:
        with contextlib.suppress(OSError):
            st = os.stat(path)
            _current.own.add((st.st_dev, st.st_ino))


def written(path: str | os.PathLike) -> None:
    """Record an output the current command wrote: it may read and replace it again."""
    rewritable(path)


def target(path: str | os.PathLike) -> Path:
    """The real path an output to ``path`` writes, or FacecleanError (one line)."""
    if os.fspath(path).endswith(("/", os.sep)):  # "out.csv/" names a folder, not a file
        raise FacecleanError(f"output {os.fspath(path)} ends in a slash: name a file")
    p = Path(path)
    real = Path(os.path.realpath(p))
    try:
        st = os.stat(real)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise FacecleanError(f"cannot write {p}: {e.strerror or e}") from None
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise FacecleanError(
            f"output {p} is {kind(st.st_mode)}: faceclean writes regular files only"
        )
    protected = _current.read - _current.own if _current is not None else set()
    if st is not None and (st.st_dev, st.st_ino) in protected:
        raise FacecleanError(f"output {p} is a file this command reads: name another file")
    return real


def distinct(*paths: str | os.PathLike | None) -> None:
    """Refuse two outputs of one command that name the same file."""
    seen: dict[str, str] = {}
    for p in paths:
        if p is None:
            continue
        real = os.path.realpath(p)
        if real in seen:
            raise FacecleanError(f"outputs {seen[real]} and {p} are the same file")
        seen[real] = str(p)


KERNEL = ("/proc", "/sys")  # pseudo-filesystems: "regular" files that are the kernel's


def kernel(path: str | os.PathLike, st: os.stat_result) -> bool:
    """Whether a "regular" file is one of the kernel's (``/proc/self/mem``, a ``/sys``
    attribute): on the filesystem of /proc or /sys, or under them once links are
    resolved. Such a file is no take: it may block, fail mid-read or never end."""
    for root in KERNEL:
        with contextlib.suppress(OSError, ValueError):
            if os.stat(root).st_dev == st.st_dev:
                return True
    try:
        real = os.path.realpath(path)
    except (OSError, ValueError):
        return False
    return any(real == root or real.startswith(root + "/") for root in KERNEL)


def kind(mode: int) -> str:
    """What a non-regular file is, in words."""
    for test, name in (
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISDIR, "a folder"),
    ):
        if test(mode):
            return name
    return "not a regular file"
