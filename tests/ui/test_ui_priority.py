"""ui/priority.py on a real loopback connection: the process at the connection's far end,
in a session of its own, yields at the nice asked (its autogroup where sessions weigh, each
of its threads where they do not); ours never does."""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest

from faceclean.ui import priority

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="no /proc")

PEER = """
import socket, sys, threading
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
threads = [threading.Thread(target=sys.stdin.read, daemon=True) for _ in range(2)]
for t in threads:
    t.start()
print(s.getsockname()[1], flush=True)
threads[0].join()  # hold the connection until told to go
"""


@contextmanager
def peer():
    """(server port, page port, the peer's pid): a process in a session of its own holding
    the far end of a loopback connection, with three threads."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-c", PEER, str(port)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, start_new_session=True)  # fmt: skip
    try:
        conn, _ = server.accept()
        yield port, int(proc.stdout.readline()), proc.pid
        conn.close()
    finally:
        proc.stdin.close()
        proc.wait(10)
        server.close()


def nices(pid: int) -> list[int]:
    return list(thread_nices(pid).values())


def thread_nices(pid: int) -> dict[int, int]:
    """{thread id: its nice} of ``pid``'s threads now."""
    out = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError):  # a thread that ended meanwhile
            out[int(task.name)] = os.getpriority(os.PRIO_PROCESS, int(task.name))
    return out


def unchanged(before: dict[int, int], after: dict[int, int]) -> bool:
    """The threads in both (this worker's come and go) kept their nice."""
    both = before.keys() & after.keys()
    return bool(both) and all(before[t] == after[t] for t in both)


def test_the_page_end_of_a_connection_yields_and_we_do_not():
    ours, base = thread_nices(os.getpid()), os.getpriority(os.PRIO_PROCESS, 0)
    own = priority._autogroup(os.getpid())
    group_nice = Path("/proc/self/autogroup").read_text() if own is not None else ""

    def at(n: int) -> list[int]:  # a runner may have started us niced already
        return [max(base, n)] * 3

    with peer() as (port, page_port, pid):
        group = priority._autogroup(pid)  # None where this system gives none
        sessions = "sessions (1) and " if group is not None and group != own else ""
        # found through the connection: its session (where it has one) and its threads
        line = priority.lower_page(port, page_port, 5)
        said = f"its browser's {sessions}threads (3) yield to the relay (nice 5)"
        assert line.startswith("the page draws on the CPU: ") and said in line, line
        assert nices(pid) == at(5)
        if sessions:
            assert Path(f"/proc/{pid}/autogroup").read_text().endswith("nice 5\n")
        assert priority.yield_cpu({pid}, 3).endswith("threads (3) yield to the relay (nice 3)")
        assert nices(pid) == at(5)  # a nicer thread is left as it is
        # ourselves, our parents and our session are never lowered, whatever is asked
        assert priority.yield_cpu({os.getpid(), os.getppid()}, 9) == ""
        assert unchanged(ours, thread_nices(os.getpid()))
        assert priority._autogroup(os.getpid()) == own
        if own is not None:
            assert Path("/proc/self/autogroup").read_text() == group_nice
            assert priority.yield_groups({pid}, 6, group) == []  # the group named is kept
        # a port nobody holds: nothing found, nothing changed, said so
        assert "not found" in priority.lower_page(port, 1, 9)
        assert nices(pid) == at(5)


def test_a_session_the_browser_does_not_lead_keeps_its_group():
    # a shell leads a session of its own and starts the peer in it: the peer shares the
    # session (as an app launched by a desktop shares the desktop's), so its group is left
    # unless the leader is part of what yields
    shell = subprocess.Popen(["sh", "-c", "sleep 30 & echo $!; wait"], stdout=subprocess.PIPE,
                             text=True, start_new_session=True)  # fmt: skip
    try:
        child = int(shell.stdout.readline())
        group = priority._autogroup(child)
        if group is None or group == priority._autogroup(os.getpid()):
            pytest.skip("no autogroups weigh on this system")
        before = Path(f"/proc/{child}/autogroup").read_text()
        assert os.getsid(child) == shell.pid != child
        assert priority.yield_groups({child}, 8) == []
        assert Path(f"/proc/{child}/autogroup").read_text() == before
        assert priority.yield_groups({shell.pid, child}, 8) == [group]
        assert Path(f"/proc/{child}/autogroup").read_text().endswith("nice 8\n")
    finally:
        os.killpg(shell.pid, 9)  # the shell and its sleep: the session's one group
        shell.wait(10)
