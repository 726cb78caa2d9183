"""The page's browser yields the CPU to the relay when the page draws on the CPU.

Why (docs/BENCHMARKS.md, issue 20): on a machine without a GPU the page's WebGL runs in
SwiftShader, on the CPUs the relay needs, and the relay's slow frames are frames where it
was runnable and not run, behind the browser's threads. Raising a nice needs no privilege
for one's own processes, and it only lowers a share where the CPU is contended. Which nice
weighs depends on how the scheduler groups tasks (sched(7)), so both are set:
- a session's autogroup nice: with autogroups (a desktop's default) each session's threads
  are one group, the CPU is shared between groups by each group's nice, and a thread's own
  nice does not weigh across them. A browser started by the relay or a driver runs in
  sessions of its own; only sessions the browser leads are set, never one it shares.
- each thread's own nice: without autogroups (turned off, or a process in a container's CPU
  cgroup, where /proc/PID/autogroup reads empty), or with the browser in the relay's own
  session, threads share by their own nice. Nice is per thread in Linux; threads started
  later take their parent thread's.

The browser is found from the page's live channel: the loopback TCP socket whose local
port is the page's end and whose remote port is the server's (/proc/net/tcp, tcp6), the
process holding that socket (/proc/PID/fd), then the whole browser: up the parents while
the program is the same (never into the relay or its parents), and every descendant of the
topmost. Linux only; elsewhere, or without /proc, nothing is changed and the reason is
said. A browser in a CPU cgroup apart from the relay's keeps its share: nice does not weigh
across cgroups.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

PROC = Path("/proc")
MAX_NICE = 19  # the lowest weight a group can be given


def lower_page(server_port: int, page_port: int, nice: int) -> str:
    """The browser holding the page's end of the connection (127.0.0.1:page_port ->
    :server_port) yields at ``nice`` (our own process and group are never touched); a line
    saying what was done."""
    if not (PROC / "self" / "stat").exists():
        return "the page's browser keeps its priority (no /proc on this system)"
    pids = _holders(_sockets(page_port, server_port))
    if not pids:
        return "the page's browser keeps its priority (its process was not found)"
    done = yield_cpu(_browser(min(pids)), nice)
    if not done:
        return "the page's browser keeps its priority (not allowed to change it)"
    return f"the page draws on the CPU: its browser's {done}; --ui-nice 0 leaves it"


def yield_cpu(pids: set[int], nice: int) -> str:
    """``pids`` but ours and our parents yield at ``nice``: their autogroups but ours, and
    each of their threads. What was set, as words ("" for nothing)."""
    pids = set(pids) - _ours()
    groups = len(yield_groups(pids, nice, _autogroup(os.getpid())))
    threads = yield_threads(pids, nice)
    said = [f"sessions ({groups})"] * (groups > 0) + [f"threads ({threads})"] * (threads > 0)
    return f"{' and '.join(said)} yield to the relay (nice {nice})" if said else ""


def yield_groups(pids: set[int], nice: int, own: str | None = None) -> list[str]:
    """The autogroups of the sessions ``pids`` lead, but ``own``, set to ``nice``; the
    groups set. A session led by another program (a desktop's, whose apps share it) is
    left: its group nice would lower every app in it."""
    done: list[str] = []
    for pid in sorted(pids):
        group = _autogroup(pid)
        if group is None or group == own or group in done or _session(pid) not in pids:
            continue
        with contextlib.suppress(OSError):  # gone, or not ours
            (PROC / str(pid) / "autogroup").write_text(str(nice))
            done.append(group)
    return done


def yield_threads(pids: set[int], nice: int) -> int:
    """Every thread of ``pids`` at nice ``nice`` at least (a nicer one is left); how many
    threads are at it now."""
    done = 0
    for pid in sorted(pids):
        with contextlib.suppress(OSError):  # gone, or not ours
            for task in (PROC / str(pid) / "task").iterdir():
                tid = int(task.name)
                with contextlib.suppress(OSError):
                    if os.getpriority(os.PRIO_PROCESS, tid) < nice:
                        os.setpriority(os.PRIO_PROCESS, tid, nice)
                    done += 1
    return done


def _ours() -> set[int]:
    """This process and its parents: never lowered."""
    out, pid = set(), os.getpid()
    while pid and pid not in out:
        out.add(pid)
        pid = _parent(pid) or 0
    return out


def _session(pid: int) -> int | None:
    """The session id of ``pid`` (None: no such process)."""
    try:
        return os.getsid(pid)
    except OSError:
        return None


def _autogroup(pid: int) -> str | None:
    """'/autogroup-N' of ``pid`` (None: none, or no such process)."""
    try:
        return (PROC / str(pid) / "autogroup").read_text().split()[0]
    except (OSError, IndexError):
        return None


def _sockets(local_port: int, remote_port: int) -> set[str]:
    """Inodes of the loopback TCP sockets from ``local_port`` to ``remote_port``."""
    found = set()
    for table in ("tcp", "tcp6"):
        with contextlib.suppress(OSError):
            for line in (PROC / "net" / table).read_text().splitlines()[1:]:
                f = line.split()  # sl local rem st tx:rx tr:when retrnsmt uid timeout inode
                if len(f) > 9 and _port(f[1]) == local_port and _port(f[2]) == remote_port:
                    found.add(f[9])
    return found - {"0"}


def _port(address: str) -> int:
    return int(address.rsplit(":", 1)[1], 16)


def _holders(inodes: set[str]) -> set[int]:
    """The processes holding any of the sockets ``inodes`` (those we may look into)."""
    links = {f"socket:[{i}]" for i in inodes}
    pids = set()
    for proc in _pids():
        with contextlib.suppress(OSError):
            for fd in (PROC / str(proc) / "fd").iterdir():
                with contextlib.suppress(OSError):
                    if os.readlink(fd) in links:
                        pids.add(proc)
                        break
    return pids


def _browser(pid: int) -> set[int]:
    """``pid``'s program as a whole: up the parents while the executable is the same, then
    the topmost one and every descendant."""
    exe, ours = _exe(pid), _ours()
    top = pid
    while True:
        parent = _parent(top)
        if parent is None or parent <= 1 or parent in ours or _exe(parent) != exe:
            break
        top = parent
    children: dict[int, list[int]] = {}
    for p in _pids():
        parent = _parent(p)
        if parent is not None:
            children.setdefault(parent, []).append(p)
    out, todo = set(), [top]
    while todo:
        p = todo.pop()
        if p not in out:
            out.add(p)
            todo += children.get(p, [])
    return out


def _pids() -> list[int]:
    return [int(p.name) for p in PROC.iterdir() if p.name.isdigit()]


def _exe(pid: int) -> str | None:
    try:
        return os.readlink(PROC / str(pid) / "exe")
    except OSError:
        return None


def _parent(pid: int) -> int | None:
    try:
        stat = (PROC / str(pid) / "stat").read_text()
    except OSError:
        return None
    return int(stat.rsplit(")", 1)[1].split()[1])  # after "pid (comm) state": ppid
