"""Worker processes, bounded and tied to their parent: the one place faceclean starts them.

``clean --jobs``, ``pairs --jobs`` and ``train`` (its torchrun ranks, its threads) use it::

    from faceclean import workers

    n, note = workers.count(args.jobs, len(todo), "files")   # capped, with the reason
    if note:
        print(note, file=sys.stderr)                         # only the CLI prints
    with workers.Pool(n, initializer=setup, initargs=(path,)) as pool:
        futures = {pool.submit(work, job): job for job in todo}
        for f in concurrent.futures.as_completed(futures):
            ...

API:

- ``cores() -> int``: the cores this process may run on (its affinity mask, not the
  machine's count).
- ``count(requested, tasks, noun="tasks", flag="--jobs") -> (n, note)``: how many
  workers to start: ``min(requested, tasks, PER_CORE * cores())``, at least 1;
  ``note`` is the line to show when the request was capped (None when it was not);
  FacecleanError when ``requested < 1``. ``tasks=None``: no task bound (threads).
- ``Pool(n, initializer=None, initargs=())``: a ``ProcessPoolExecutor`` (spawn: never a
  fork of a process that runs threads or MediaPipe) whose ``submit(fn, *args)`` runs
  ``fn`` in a worker. Each worker dies with this process whatever ends it (SIGKILL
  too), ignores Ctrl-C (the terminal sends it to the whole group; the parent decides),
  and on SIGTERM unwinds its task (``atomic_open`` deletes its temporary file) and
  exits. Leaving the ``with`` block normally waits for the work; leaving it by an
  exception (Ctrl-C, SIGTERM, a failure) cancels what has not started and terminates
  the workers instead (SIGTERM, then SIGKILL after ``GRACE`` s). ``fn``, the
  initializer and their arguments must pickle (module-level functions). Create the
  pool and submit from the thread that outlives it (the main thread): Linux ties the
  death signal to the thread that started the worker.
- ``die_with_parent(parent=None)``: in any child process (a pool worker, a torchrun
  rank): SIGTERM to itself when ``parent`` (default: its parent now) dies, by
  ``prctl(PR_SET_PDEATHSIG)`` on Linux, and by a thread that polls the parent's pid
  every ``POLL`` s everywhere (the fallback, and the backstop: ``GRACE`` s after the
  parent is gone the process exits, whatever it was doing).
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any

from faceclean.errors import FacecleanError

PER_CORE = 2  # workers per core at most (a worker waits on I/O part of the time)
POLL = 0.5  # s between two looks at the parent's pid
GRACE = 5.0  # s a worker has to unwind its task before it is killed
EXIT = 143  # a worker's exit status when it stops because its parent did (128 + SIGTERM)
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def cores() -> int:
    """Cores this process may run on (``taskset``, cgroup cpusets), at least 1."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):  # not Linux
        return max(os.cpu_count() or 1, 1)


def count(
    requested: int, tasks: int | None, noun: str = "tasks", flag: str = "--jobs"
) -> tuple[int, str | None]:
    """(workers to start, the line saying why when fewer than requested)."""
    if requested < 1:
        raise FacecleanError(f"{flag} must be at least 1 (got {requested})")
    c = cores()
    limits = [(PER_CORE * c, f"at most {PER_CORE} per core on {c} core{'s' * (c > 1)}")]
    if tasks is not None:
        limits.append((max(tasks, 1), f"{tasks} {noun}"))
    cap, why = min(limits)
    if requested <= cap:
        return requested, None
    return cap, f"{flag} {requested} capped at {cap} ({why})"


# -- in the worker ---------------------------------------------------------------------
class ParentGone(BaseException):
    """Raised in a worker's task on SIGTERM: never caught by ``except Exception``, so the
    task unwinds (temporary outputs removed) and the worker exits."""


# blocked across a worker's spawn (SIGHUP: POSIX only)
_SPAWN_BLOCKED = {getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)}
_busy = False  # a task is running (SIGTERM unwinds it) or not (SIGTERM exits at once)
_stopping = False


def _on_term(signum: int, frame: object) -> None:
    global _stopping
    if _stopping:  # a second signal while unwinding: let the unwinding finish
        return
    _stopping = True
    if _busy:
        raise ParentGone
    os._exit(EXIT)


def _pdeathsig(signum: int) -> bool:
    """Ask Linux to send ``signum`` when the parent (thread) exits; False elsewhere."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, ctypes.c_ulong(signum), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent: int) -> None:
    while os.getppid() == parent:  # reparented (to init or a subreaper) once it died
        time.sleep(POLL)
    os.kill(os.getpid(), signal.SIGTERM)  # the path PDEATHSIG takes
    time.sleep(GRACE)
    os._exit(EXIT)  # still here: the task did not unwind in time


def die_with_parent(parent: int | None = None) -> None:
    """Make this process stop when ``parent`` dies (see the module docstring)."""
    parent = os.getppid() if parent is None else parent
    _pdeathsig(signal.SIGTERM)
    if os.getppid() != parent:  # it died before the death signal was set
        os._exit(EXIT)
    threading.Thread(target=_watch, args=(parent,), daemon=True, name="parent-watch").start()


def _start(parent: int, initializer: Callable[..., Any] | None, initargs: Sequence) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C: the parent stops the pool
    signal.signal(signal.SIGTERM, _on_term)
    signal.signal(signal.SIGHUP, _on_term)
    if hasattr(signal, "pthread_sigmask"):  # blocked since the spawn (Pool.submit): a
        # pending Ctrl-C is dropped, a pending SIGTERM or SIGHUP now ends this worker quietly
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _SPAWN_BLOCKED)
    die_with_parent(parent)
    if initializer is not None:
        initializer(*initargs)


def _call(fn: Callable[..., Any], args: tuple, kwargs: dict) -> Any:
    global _busy
    _busy = True
    try:
        return fn(*args, **kwargs)
    except ParentGone:
        os._exit(EXIT)
    finally:
        _busy = False


# -- in the parent ---------------------------------------------------------------------
class Pool:
    """Worker processes that die with this one (see the module docstring)."""

    def __init__(
        self,
        workers: int,
        initializer: Callable[..., Any] | None = None,
        initargs: Sequence = (),
    ) -> None:
        self._before = set(multiprocessing.active_children())
        self._executor = ProcessPoolExecutor(
            workers,
            multiprocessing.get_context("spawn"),
            initializer=_start,
            initargs=(os.getpid(), initializer, tuple(initargs)),
        )

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        # a worker is spawned here, on demand: SIGINT blocked while it is, so a Ctrl-C
        # during its start-up waits (the child inherits the mask until ``_start`` ignores
        # it) instead of printing a KeyboardInterrupt traceback from its imports; the
        # parent gets its own Ctrl-C as soon as the mask is restored
        # SIGTERM and SIGHUP too: one landing in the parent between the child's start and
        # the parent writing its start-up data to it left a child no one stopped, reading
        # an empty pipe ("EOFError: Ran out of input" and a traceback on stderr)
        if not hasattr(signal, "pthread_sigmask"):
            return self._executor.submit(_call, fn, args, kwargs)
        old = signal.pthread_sigmask(signal.SIG_BLOCK, _SPAWN_BLOCKED)
        try:
            return self._executor.submit(_call, fn, args, kwargs)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)

    def terminate(self) -> None:
        """Cancel the work not started and stop every worker now (bounded: ``GRACE`` s)."""
        # the executor's manager thread, kept: shutdown(wait=False) drops the executor's
        # reference to it, so a later shutdown(wait=True) would not wait for it
        manager = getattr(self._executor, "_executor_manager_thread", None)
        self._executor.shutdown(wait=False, cancel_futures=True)
        mine = [p for p in multiprocessing.active_children() if p not in self._before]
        for p in mine:
            with contextlib.suppress(OSError, ValueError):
                p.terminate()
        # wait on the exit sentinels (the executor's own thread reaps the processes)
        left = {p.sentinel: p for p in mine}
        deadline = time.monotonic() + GRACE
        while left and (wait_s := deadline - time.monotonic()) > 0:
            for ready in multiprocessing.connection.wait(list(left), wait_s):
                left.pop(ready)
        for p in left.values():
            with contextlib.suppress(OSError, ValueError):
                p.kill()
        # join the executor's manager thread now that its workers are gone: left running,
        # it closes its wake-up pipe while the interpreter's exit hook writes to it
        # (CPython 3.11: "OSError: Bad file descriptor" and a traceback printed at exit)
        self._executor.shutdown(wait=True)
        if manager is not None and manager.is_alive():
            manager.join(GRACE)

    def __enter__(self) -> Pool:
        return self

    def __exit__(self, kind: type | None, error: BaseException | None, tb: object) -> None:
        if kind is None:
            self._executor.shutdown(wait=True)
        else:
            self.terminate()
