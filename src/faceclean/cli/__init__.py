"""The ``faceclean`` command. Thin: parse, call one library function, print.

Each subcommand is a module ``faceclean.cli.<name>`` with ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Modules import heavy things
(torch above all) inside ``run``, so ``faceclean --help`` stays fast and torch-free.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import importlib.util
import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterator

from faceclean.errors import FacecleanError

# In the order --help lists them.
COMMANDS: tuple[str, ...] = (
    "demo", "clean", "calibrate", "info", "convert", "tune",
    "corrupt", "synth",
    "pairs", "train", "eval", "plot", "export", "bench",
    "relay", "replay", "track",
    "report", "face-mesh", "ui",
    "fuzz",
)  # fmt: skip


def _modules() -> dict[str, object]:
    found = {}
    for name in COMMANDS:
        modname = f"faceclean.cli.{name.replace('-', '_')}"
        if importlib.util.find_spec(modname) is not None:
            found[name] = importlib.import_module(modname)
    return found


class Parser(argparse.ArgumentParser):
    """argparse's, but a bad command line is one line, as every other refusal is, not the
    usage block and then the error: the options are one ``--help`` away."""

    def error(self, message: str):  # type: ignore[override]
        command = self.prog.removeprefix("faceclean").strip()
        at = f"{command}: " if command else ""
        self.exit(2, f"faceclean: {at}{message} ({self.prog} --help shows the options)\n")


def parser() -> argparse.ArgumentParser:
    p = Parser(  # its subcommands' parsers are Parsers too (add_subparsers: type(self))
        prog="faceclean",
        description="Clean facial-capture blendshape animation, offline or live.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for name, mod in _modules().items():
        sp = sub.add_parser(
            name,
            help=mod.HELP,
            description=mod.HELP,
            epilog=getattr(mod, "EPILOG", None),  # a worked example, where a command has one
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        mod.add_arguments(sp)
        sp.set_defaults(_run=mod.run)
    return p


class Terminated(BaseException):
    """SIGTERM or SIGHUP, raised where the command is: atomic outputs clean up as on Ctrl-C."""


EXIT_GRACE_S = 10  # s a stopped command has to unwind and exit before the kernel ends it


def _deadline() -> None:
    """Once a command is told to stop: if unwinding or the interpreter's exit then hangs
    (a native library's teardown: MediaPipe's graph, seen once under load), SIGALRM's
    default action ends the process ``EXIT_GRACE_S`` s later, without needing the GIL."""
    if hasattr(signal, "alarm") and signal.getsignal(signal.SIGALRM) == signal.SIG_DFL:
        signal.alarm(EXIT_GRACE_S)


@contextlib.contextmanager
def stopping(stop: Callable[[], None]) -> Iterator[None]:
    """A live command's scope: its first SIGINT or SIGTERM calls ``stop`` (the loop ends
    and the command goes on to save and say what it has); a later one only bounds that by
    ``_deadline``, never aborts it (``timeout`` signals the process and its group: the
    second signal lost the relay's recording while it was saved)."""
    told = []

    def on_signal(signum: int, frame: object) -> None:
        if told:
            _deadline()
        else:
            told.append(signum)
            stop()

    on_main = threading.current_thread() is threading.main_thread()
    caught = (signal.SIGINT, signal.SIGTERM)
    old = {s: signal.signal(s, on_signal) for s in caught} if on_main else {}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


@contextlib.contextmanager
def _command() -> Iterator[None]:
    """One command's scope: the output-path policy (io.paths), SIGTERM as an exception,
    numpy's floating-point warnings off (results are checked explicitly instead)."""
    import numpy as np

    from faceclean.io import paths

    def terminate(signum: int, frame: object) -> None:
        _deadline()
        raise Terminated

    on_main = threading.current_thread() is threading.main_thread()
    caught = (signal.SIGTERM, signal.SIGHUP)
    old = {s: signal.signal(s, terminate) for s in caught} if on_main else {}
    try:
        with paths.command(), np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def main(argv: list[str] | None = None) -> int:
    for stream in (sys.stdout, sys.stderr):  # a terminal that cannot show a prompt's or a
        with contextlib.suppress(AttributeError, ValueError):  # name's letters gets \u escapes
            stream.reconfigure(errors="backslashreplace")
    try:  # Ctrl-C while the commands import (a second or so): no traceback either
        p = parser()
        args = p.parse_args(argv)
    except KeyboardInterrupt:
        print("faceclean: interrupted", file=sys.stderr)
        return 130
    if getattr(args, "_run", None) is None:
        p.print_help()
        return 2
    try:
        with _command():
            return int(args._run(args) or 0)
    except FacecleanError as e:
        print(f"faceclean: {_short(str(e))}", file=sys.stderr)
        return 2
    except Terminated:
        print("faceclean: terminated", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        _deadline()
        print("faceclean: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 1
    except (OSError, MemoryError) as e:
        if os.environ.get("FACECLEAN_DEBUG"):
            raise
        why = {errno.ENOSPC: "the disk is full: free some space and run it again",
               errno.EDQUOT: "the disk quota is spent: free some space and run it again",
               errno.EFBIG: "the output passes this system's file size limit (ulimit -f): "
               "raise it, or write less"}.get(getattr(e, "errno", None))  # fmt: skip
        said = f"{why} (no output was left half-written)" if why else str(e)
        print(f"faceclean: {_short(said)}", file=sys.stderr)
        return 1
    except Exception as e:  # never a traceback for a user; FACECLEAN_DEBUG=1 shows it
        if os.environ.get("FACECLEAN_DEBUG"):
            raise
        print(f"faceclean: internal error: {type(e).__name__}: {e}", file=sys.stderr)
        return 1


MAX_MESSAGE = 2000  # characters: room for a list of the 52 names; a 100k-character value is cut


def _short(message: str) -> str:
    """``message`` on one line of at most about MAX_MESSAGE characters: a long middle (a
    quoted value, as a user typed it) is cut, its length said."""
    message = " ".join(message.splitlines())
    if len(message) <= MAX_MESSAGE:
        return message
    head, tail = message[: MAX_MESSAGE - 400], message[-300:]
    return f"{head} ... [{len(message) - len(head) - len(tail)} characters cut] ... {tail}"
