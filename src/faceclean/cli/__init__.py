"""The ``faceclean`` command. Thin: parse, call one library function, print.

Each subcommand is a module ``faceclean.cli.<name>`` with ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Modules import heavy things
(torch above all) inside ``run``, so ``faceclean --help`` stays fast and torch-free.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import sys

from faceclean.errors import FacecleanError

# In the order --help lists them.
COMMANDS: tuple[str, ...] = (
    "demo", "clean", "calibrate", "info", "convert", "tune",
    "corrupt", "synth",
    "train", "eval", "plot", "export", "bench",
    "relay", "replay",
    "report", "face-mesh",
    "fuzz",
)  # fmt: skip


def _modules() -> dict[str, object]:
    found = {}
    for name in COMMANDS:
        modname = f"faceclean.cli.{name.replace('-', '_')}"
        if importlib.util.find_spec(modname) is not None:
            found[name] = importlib.import_module(modname)
    return found


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
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


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = p.parse_args(argv)
    if getattr(args, "_run", None) is None:
        p.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except FacecleanError as e:
        print(f"faceclean: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("faceclean: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 1
    except (OSError, MemoryError) as e:
        if os.environ.get("FACECLEAN_DEBUG"):
            raise
        print(f"faceclean: {e}", file=sys.stderr)
        return 1
    except Exception as e:  # never a traceback for a user; FACECLEAN_DEBUG=1 shows it
        if os.environ.get("FACECLEAN_DEBUG"):
            raise
        print(f"faceclean: internal error: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
