"""faceclean.workers: the pool is bounded, and its workers die with their parent.

Real processes and real signals: a parent script starts a Pool whose workers sit in a
task (an atomic write left open), the test kills the parent and polls, up to a deadline,
until every worker is gone and no temporary file is left.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from helpers import REPO

from faceclean import workers
from faceclean.errors import FacecleanError

DEADLINE = 60.0  # s: the most a poll below waits (a loaded 2-core machine)


def test_count_caps_at_the_tasks_and_a_multiple_of_the_cores():
    cap = workers.PER_CORE * workers.cores()
    assert workers.count(1, 10) == (1, None)
    n, note = workers.count(100_000, 1, "file")
    assert n == 1 and note == "--jobs 100000 capped at 1 (1 file)"
    n, note = workers.count(100_000, 10**6, "files")
    assert n == cap and f"capped at {cap}" in note and "per core" in note
    n, note = workers.count(100_000, None, flag="--threads")
    assert n == cap and note.startswith("--threads 100000 capped")
    for bad in (0, -3):
        with pytest.raises(FacecleanError, match="--jobs must be at least 1"):
            workers.count(bad, 5)


def test_pool_runs_tasks_and_returns_their_results():
    with workers.Pool(2) as pool:
        futures = [pool.submit(pow, 2, k) for k in range(6)]
        assert sorted(f.result() for f in futures) == [2**k for k in range(6)]


PARENT = '''
import multiprocessing, os, sys, time
from faceclean import workers
from faceclean.io.atomic import atomic_open


def no_prctl():
    """Clear the death signal again: the parent-pid watch alone must stop the worker."""
    import ctypes

    ctypes.CDLL(None).prctl(1, ctypes.c_ulong(0), 0, 0, 0)  # PR_SET_PDEATHSIG, none


def hold(path):
    """An atomic write that never completes: its temporary file stays until unwound."""
    with atomic_open(path, "wb") as f:
        f.write(b"partial")
        f.flush()
        time.sleep(3600)


if __name__ == "__main__":
    out, fallback = sys.argv[1], sys.argv[2] == "poll"
    pool = workers.Pool(2, initializer=no_prctl if fallback else None)
    with pool:
        futures = [pool.submit(hold, os.path.join(out, f"o{i}.bin")) for i in range(2)]
        while len(multiprocessing.active_children()) < 2:
            time.sleep(0.05)
        print(" ".join(str(p.pid) for p in multiprocessing.active_children()), flush=True)
        time.sleep(3600)
'''


def _script(tmp_path: Path) -> Path:
    p = tmp_path / "parent.py"  # spawned workers re-import it: its functions are theirs
    p.write_text(textwrap.dedent(PARENT))
    return p


def _alive(pid: int) -> bool:
    """The process exists and is not a zombie (a container's init may never reap)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in ("Z", "X")


def _poll(condition, deadline: float = DEADLINE) -> bool:
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.1)
    return condition()


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
@pytest.mark.parametrize("how", ["prctl", "poll"])
@pytest.mark.parametrize(
    "sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT], ids=["kill", "term", "int"]
)
def test_workers_die_with_their_parent_and_leave_no_temporary_file(tmp_path, sig, how):
    if how == "poll" and sig != signal.SIGKILL:
        pytest.skip("the fallback matters when the parent cannot act: SIGKILL")
    out = tmp_path / "out"
    out.mkdir()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO / "src"), str(REPO / "tests")]))
    parent = subprocess.Popen(
        [sys.executable, str(_script(tmp_path)), str(out), how],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,  # its own group: SIGINT goes to all, as Ctrl-C does
    )
    pids: list[int] = []
    try:
        ready, _, _ = select.select([parent.stdout], [], [], DEADLINE)
        pids = [int(p) for p in parent.stdout.readline().split()] if ready else []
        assert len(pids) == 2, "the pool never started its two workers"
        assert _poll(lambda: len(list(out.glob(".*.tmp"))) == 2), "the workers never wrote"
        if sig == signal.SIGINT:
            os.killpg(parent.pid, sig)  # Ctrl-C: the whole foreground group
        else:
            os.kill(parent.pid, sig)  # the parent alone
        parent.wait(timeout=DEADLINE)
        assert _poll(lambda: not any(_alive(p) for p in pids)), [p for p in pids if _alive(p)]
        assert not list(out.iterdir()), [p.name for p in out.iterdir()]  # unwound, removed
        err = parent.stderr.read()  # the script's own KeyboardInterrupt; none from workers
        assert err.count("Traceback") == (sig == signal.SIGINT), err[-800:]
    finally:
        for p in [parent.pid, *pids]:
            if _alive(p):
                with contextlib.suppress(ProcessLookupError):
                    os.kill(p, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            parent.wait(timeout=DEADLINE)
