"""A fork server for the command-line tests: ``faceclean ARGS`` as a real child process,
forked from one that has imported faceclean once, instead of a new interpreter each time.

Why: the red team runs the CLI some 800 times; a fresh interpreter spends ~0.5 s of each
run importing numpy and the commands before it reads its first argument (half of the
suite's time on 2 cores). A forked child starts with those modules loaded and is
otherwise what ``python -m faceclean ARGS`` is: its own process and process group, its
own file descriptors 0-2 (the caller's files), working folder, environment and address-
space limit, ``faceclean.cli.main`` run as ``__main__`` runs it, Python's own exit path
(thread joins, atexit, streams flushed; not the teardown of the server's modules: see
``_exit``) and its exit status (-N when a signal ended it).

    from zygote import run
    rc, out, err = run(["info", "take.csv"], cwd=..., env=..., mem=..., stdin=fd, timeout=90)

``run`` returns None when the command outlived ``timeout`` s (its group is killed).
The server is started on first use, one per test process (xdist workers each have theirs),
with the environment of the first call; a call with another environment, or where fork
is unavailable, falls back to a fresh interpreter.

Server protocol (a Unix socket pair): a request is one JSON message {"argv", "cwd",
"env", "mem"}, its length (8 bytes) sent with four descriptors (stdin, stdout, stderr, a
reply socket). A monitor process forks the command, writes {"pid"} then {"status"} to the
reply socket, and exits.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

HERE = Path(__file__).resolve().parent
_lock = threading.Lock()
_server: tuple[subprocess.Popen, socket.socket, dict] | None = None


# -- the server (runs as ``python tests/zygote.py FD``) ------------------------------------
# What commands import when they run, loaded once in the server: the tuner's scipy alone is
# 1.2 s of every `tune` and `eval` child (none starts a thread or warns on import).
PRELOAD = ("faceclean.cli.clean_take", "faceclean.cli.clean_batch", "faceclean.io.stream",
           "faceclean.relay.loop", "faceclean.report.build", "faceclean.filters.compiled",
           "faceclean.filters.tune", "faceclean.evaluation.evaluate",
           "faceclean.learned.tracker_map")  # fmt: skip


def _serve(fd: int) -> None:
    import resource
    import signal
    import warnings

    with warnings.catch_warnings(record=True) as caught:  # warm: what every command loads
        warnings.simplefilter("always")
        import importlib

        import faceclean.cli

        faceclean.cli.parser()
        for name in PRELOAD:
            importlib.import_module(name)
    if caught:  # a warning shown here would be hidden from every child: never preload one
        raise SystemExit(f"zygote: preloading warned: {caught[0].message}")
    import gc

    gc.freeze()  # what the server loaded: never scanned (nor its pages copied) by a child's gc
    control = socket.socket(fileno=fd)
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # monitors are reaped by the kernel
    while True:
        try:
            head, fds, _, _ = socket.recv_fds(control, 8, 4)
            head += _read(control, 8 - len(head))  # a stream: anything may come in pieces
            size = int.from_bytes(head, "big")
            msg = _read(control, size) if len(head) == 8 else b""
        except OSError:
            return
        if not msg or len(msg) < size:
            return  # the test process closed its end
        if os.fork() == 0:  # the monitor
            control.close()
            signal.signal(signal.SIGCHLD, signal.SIG_DFL)
            req, reply = json.loads(msg), socket.socket(fileno=fds[3])
            pid = os.fork()
            if pid == 0:  # the command
                reply.close()
                os.setsid()  # its own group: a timeout kills it and its children
                resource.setrlimit(resource.RLIMIT_AS, (req["mem"], req["mem"]))
                for i in range(3):
                    os.dup2(fds[i], i)
                for f in fds[:3]:
                    if f > 2:
                        os.close(f)
                os.chdir(req["cwd"])
                os.environ.clear()
                os.environ.update(req["env"])
                _command(req["argv"])
            os.close(fds[0]), os.close(fds[1]), os.close(fds[2])
            reply.sendall(json.dumps({"pid": pid}).encode() + b"\n")
            _, status = os.waitpid(pid, 0)
            code = -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)
            reply.sendall(json.dumps({"status": code}).encode() + b"\n")
            os._exit(0)
        for f in fds:
            os.close(f)


def _read(sock: socket.socket, size: int) -> bytes:
    """``size`` bytes, or fewer where the other end closed first."""
    got = b""
    while len(got) < size:
        chunk = sock.recv(size - len(got))
        if not chunk:
            break
        got += chunk
    return got


def _command(argv: list[str]) -> None:
    """``python -m faceclean ARGV`` from here on: main, then Python's own exit."""
    import io
    import traceback

    # fresh text streams on the new descriptors (the server's were buffered on its own), with
    # the encodings and error handlers Python chose for the server's (the same environment)
    def text(fd: int, like, **kw) -> io.TextIOWrapper:
        mode = "r" if fd == 0 else "w"
        raw = io.FileIO(fd, mode, closefd=False)
        return io.TextIOWrapper(raw, encoding=like.encoding, errors=like.errors, **kw)

    sys.stdin = text(0, sys.__stdin__)
    sys.stdout = text(1, sys.__stdout__, write_through=False)
    sys.stderr = text(2, sys.__stderr__, write_through=True)
    sys.argv = ["faceclean", *argv]
    try:
        from faceclean.cli import main

        code = main(argv)
    except SystemExit as e:  # argparse's usage errors, sys.exit in a command
        code = e.code
    except BaseException:
        traceback.print_exc()
        code = 1
    if code is None:
        code = 0
    elif not isinstance(code, int):
        print(code, file=sys.stderr)
        code = 1
    _exit(code)


def _exit(code: int) -> None:
    """Python's exit path up to its teardown: thread joins, atexit handlers, a collection
    of what the command left in cycles (a finaliser that fails still prints), the standard
    streams flushed. The teardown of every module the server loaded is skipped: 0.2 s of
    each child, most of it copying the pages its refcount writes touch. A command closes
    what it writes itself; one that left it to the teardown would show here as a short file."""
    import atexit
    import gc
    import threading

    threading._shutdown()
    atexit._run_exitfuncs()
    gc.collect()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            code = code or 120  # what Python exits with when it cannot flush stdout
    os._exit(code)


# -- the client -----------------------------------------------------------------------------
def _start(env: dict) -> tuple[subprocess.Popen, socket.socket, dict]:
    mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    proc = subprocess.Popen(
        [sys.executable, str(Path(__file__).resolve()), str(theirs.fileno())],
        pass_fds=[theirs.fileno()],
        env=env,
        cwd=str(HERE.parent),
        stdin=subprocess.DEVNULL,
    )
    theirs.close()
    return proc, mine, env


def run(argv, *, cwd, env: dict, mem: int, stdin=None, timeout: float):
    """(returncode, stdout bytes, stderr bytes), or None past ``timeout`` s."""
    global _server
    with _lock:
        if _server is None or _server[0].poll() is not None:
            _server = _start(env)
        proc, control, server_env = _server
    if env != server_env or not hasattr(os, "fork"):
        return _fresh(argv, cwd=cwd, env=env, mem=mem, stdin=stdin, timeout=timeout)
    reply, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        close_in = stdin is None
        in_fd = os.open(os.devnull, os.O_RDONLY) if close_in else _fd(stdin)
        try:
            msg = json.dumps({"argv": list(argv), "cwd": str(cwd), "env": env, "mem": mem})
            msg = msg.encode()
            fds = [in_fd, out.fileno(), err.fileno(), theirs.fileno()]
            with _lock:  # its length with the descriptors, then the message
                socket.send_fds(control, [len(msg).to_bytes(8, "big")], fds)
                control.sendall(msg)
        finally:
            theirs.close()
            if close_in:
                os.close(in_fd)
        with reply:
            lines = _Lines(reply)
            started = lines.get(30.0)
            if started is None:
                raise RuntimeError("zygote: no child started within 30 s")
            pid = started["pid"]
            got = lines.get(timeout)
            if got is None:  # still running: kill its group, then collect its status
                import signal

                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(pid, signal.SIGKILL)
                lines.get(30.0)
                return None
        out.seek(0), err.seek(0)
        return got["status"], out.read(), err.read()


def _fd(stdin) -> int:
    return stdin if isinstance(stdin, int) else stdin.fileno()


class _Lines:
    """JSON lines from the monitor's reply socket, each within a deadline."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock, self.buf = sock, b""

    def get(self, timeout: float) -> dict | None:
        import time

        end = time.monotonic() + timeout
        while b"\n" not in self.buf:
            left = end - time.monotonic()
            if left <= 0:
                return None
            self.sock.settimeout(left)
            try:
                chunk = self.sock.recv(4096)
            except TimeoutError:
                return None
            if not chunk:
                raise RuntimeError("zygote: the monitor died without a status")
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return json.loads(line)


def _fresh(argv, *, cwd, env, mem, stdin, timeout):
    """The plain way: a new interpreter (a call with another environment)."""
    import resource
    import signal

    def limits() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
        os.setsid()

    proc = subprocess.Popen(
        [sys.executable, "-m", "faceclean", *argv],
        cwd=cwd, env=env, preexec_fn=limits,
        stdin=stdin if stdin is not None else subprocess.DEVNULL,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return None
    return proc.returncode, out, err


if __name__ == "__main__":
    _serve(int(sys.argv[1]))
