"""Atomic output: write to a temporary file beside the target, then rename.

A failed, refused or interrupted write (an exception, Ctrl-C, SIGTERM: the CLI turns it
into an exception) leaves no file behind and never touches an existing one, so OUT == IN
is safe (the input was read whole before the rename replaces it). What a path may name
is decided by ``io.paths.target`` (no FIFO, device or folder; not another input).
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from faceclean.errors import FacecleanError
from faceclean.io import paths


def writable(path: str | os.PathLike) -> Path:
    """The real file an output ``path`` names (symlinks followed), once checked: its
    folder exists, it is not a folder, and ``paths.target`` accepts it."""
    given = Path(path)
    folder = given.parent if str(given.parent) else Path(".")
    if not folder.is_dir():
        raise FacecleanError(f"output folder does not exist: {folder}")
    if given.is_dir():
        raise FacecleanError(f"output path is a folder: {given}")
    target = paths.target(path)
    if not target.parent.is_dir():  # a symlink into a folder that is not there
        raise FacecleanError(f"output folder does not exist: {target.parent} ({given} leads there)")
    if target.exists() and not target.stat().st_mode & 0o222:
        raise FacecleanError(
            f"{given} is read-only: nothing replaces it unasked (make it writable, or name "
            "another file)"
        )
    return target


def check_writable(*outputs: str | os.PathLike | None) -> None:
    """Refuse now, before any work, what a later write to each output would refuse (the
    ``-o`` policy: ``writable``), and two outputs naming one file. A command that writes
    at its end (a relay's ``--record``, ``train --out``, ``eval --json``) calls this at
    its start; None entries (options not given) are skipped."""
    paths.distinct(*outputs)
    for out in outputs:
        if out is not None:
            _probe(writable(out))


def _probe(target: Path) -> None:
    """Create and remove a file beside ``target``, as the write will: a folder that takes
    no new file (read-only, /proc) is refused at the start, not after the work."""
    tmp = _temporary(target)
    try:
        os.close(os.open(tmp, _FLAGS, 0o600))
    except OSError as e:
        raise FacecleanError(f"cannot write in {target.parent}: {e.strerror or e}") from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)


def _temporary(target: Path) -> Path:
    """A new hidden name beside ``target`` (64 random bits: it meets no existing file)."""
    return target.parent / f".{target.name[:100]}.{secrets.token_hex(8)}.tmp"


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "wb") -> Iterator[IO]:
    """Open a temporary file for writing; on success it replaces ``path`` atomically."""
    target = writable(path)
    tmp: Path | None = None
    try:
        # Not tempfile.mkstemp: a signal handled between the file's creation and mkstemp's
        # return (the CLI raises on SIGTERM) left a file the caller had no name for. Here
        # the name is bound first; a 64-bit random name meets an existing file never.
        for _ in range(100):
            tmp = _temporary(target)
            try:
                fd = os.open(tmp, _FLAGS, 0o600)
                break
            except FileExistsError:
                continue
            except OSError as e:  # e.g. /proc, a read-only folder: not ours to explain
                tmp = None
                raise FacecleanError(
                    f"cannot write in {target.parent}: {e.strerror or e}"
                ) from None
        else:
            tmp = None
            raise FacecleanError(f"cannot create a temporary file beside {target}")
        kwargs = {"newline": ""} if "b" not in mode else {}
        with os.fdopen(fd, mode, **kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        pending = _pending.get()
        if pending is not None:  # in ``together``: renamed when all its files are written
            pending.append((tmp, target))
            return
        _commit(tmp, target)
    except BaseException:
        if tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise


def _commit(tmp: Path, target: Path) -> None:
    """The written temporary ``tmp`` replaces ``target`` (with its permissions)."""
    if target.exists():
        os.chmod(tmp, target.stat().st_mode & 0o777)
    else:
        os.chmod(tmp, 0o644)
    os.replace(tmp, target)
    paths.written(target)


# the (temporary, target) pairs written inside ``together``, waiting; None outside it
_pending: contextvars.ContextVar[list[tuple[Path, Path]] | None] = contextvars.ContextVar(
    "faceclean_atomic_pending", default=None
)


@contextlib.contextmanager
def together() -> Iterator[None]:
    """Every ``atomic_open`` (``io.save``, ``atomic_write``) in the block writes its
    temporary file, and none replaces its target until the block ends well: then all do,
    one rename after another. A block that fails (a full disk at the second file, a
    refusal, Ctrl-C) replaces none of them, and leaves no temporary file: a command that
    writes two files (``corrupt --truth-out``) never leaves one new beside one old."""
    pending: list[tuple[Path, Path]] = []
    token = _pending.set(pending)
    try:
        try:
            yield
        finally:
            _pending.reset(token)
        while pending:
            _commit(*pending[0])
            pending.pop(0)
    except BaseException:  # those not yet renamed are removed
        for tmp, _ in pending:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise


def atomic_write(path: str | os.PathLike, data: bytes | str) -> None:
    """Write ``data`` to ``path`` atomically."""
    mode = "wb" if isinstance(data, bytes) else "w"
    with atomic_open(path, mode) as f:
        f.write(data)
