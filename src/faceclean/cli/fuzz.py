"""``faceclean fuzz [--target NAME] [--examples N | --seconds S]``: the long fuzz run.

Feeds every file reader and relay decoder (or one) arbitrary and mutated real inputs
(faceclean.evaluation.fuzz) and prints, per target, how many inputs were tried, accepted and
refused. Exit 0 when nothing broke the policy, 1 with the failure and its input otherwise.
"""

from __future__ import annotations

import argparse
import importlib.util

HELP = "fuzz the readers and relay decoders (hypothesis), reporting inputs tried and failures"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from faceclean.evaluation.fuzz import TARGETS

    p.add_argument("--target", choices=TARGETS, action="append", help="repeatable (default: all)")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--examples", type=int, metavar="N", help="inputs per target")
    budget.add_argument("--seconds", type=float, metavar="S", help="seconds per target")
    p.add_argument("--save", metavar="FILE", help="write a failing input to this file")
    p.add_argument(
        "--generated",
        action="store_true",
        help="also run the structure-aware cases of tests/generated.py (source checkout): "
        "--set and preset values, JSON/NPZ/glTF structure, OSC and Live Link packets",
    )


def run(args: argparse.Namespace) -> int:
    import sys

    from faceclean.errors import FacecleanError
    from faceclean.evaluation import fuzz
    from faceclean.io.atomic import atomic_write

    if importlib.util.find_spec("hypothesis") is None:
        raise FacecleanError("fuzz needs hypothesis: pip install 'faceclean[dev]'")
    examples, seconds = args.examples, args.seconds
    if examples is None and seconds is None:
        examples = 10_000
    if (examples is not None and examples < 1) or (seconds is not None and not seconds > 0):
        raise FacecleanError("--examples must be >= 1 and --seconds > 0")
    if examples is not None and examples > 10**9 or seconds is not None and seconds > 1e7:
        raise FacecleanError("--examples at most 1e9, --seconds at most 1e7")
    total = _generated(examples, seconds) if args.generated else 0
    for target in args.target or fuzz.TARGETS:
        report = fuzz.run(
            target,
            examples=examples,
            seconds=seconds,
            on_batch=lambda r: print(f"  {r.target}: {r.tried} so far", end="\r", flush=True),
        )
        total += report.tried
        print(
            f"{target:13s} tried {report.tried:8d}  accepted {report.accepted:7d}  "
            f"refused {report.refused:8d}  {report.seconds:7.1f} s  "
            f"{report.tried / max(report.seconds, 1e-9):7.0f}/s  "
            + ("FAILED" if report.failure else "ok"),
            flush=True,
        )
        if report.failure:
            print(f"faceclean: {target}: {report.failure}", file=sys.stderr)
            print(f"faceclean: input: {fuzz.failing_example(report)}", file=sys.stderr)
            if args.save and report.failing_input is not None:
                atomic_write(args.save, report.failing_input)
                print(f"faceclean: input saved to {args.save}", file=sys.stderr)
            return 1
    print(f"all targets: {total} inputs, no failure")
    return 0


def _generated(examples: int | None, seconds: float | None) -> int:
    """Run every case of tests/generated.py (dev-only, beside the package in a checkout)
    for ``examples`` inputs or ``seconds`` each; FacecleanError names the first failure."""
    import importlib.util
    import time
    from pathlib import Path

    from hypothesis import HealthCheck, Verbosity, given, settings

    from faceclean.errors import FacecleanError

    path = Path(__file__).resolve().parents[3] / "tests" / "generated.py"
    if not path.is_file():
        raise FacecleanError("--generated needs a source checkout (tests/generated.py)")
    spec = importlib.util.spec_from_file_location("faceclean_generated_cases", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    total = 0
    for name, (strategy, check) in module.CASES.items():
        start = time.monotonic()
        stop = start + seconds if seconds is not None else float("inf")
        tried = [0]
        counted = _counted(check, tried, stop)

        budget = settings(
            max_examples=examples or 10**9,
            deadline=None,
            database=None,
            suppress_health_check=list(HealthCheck),
            verbosity=Verbosity.quiet,  # a failure is reported below, in one line
        )
        try:
            budget(given(strategy)(counted))()
        except _TimeUp:
            pass
        except AssertionError as e:
            raise FacecleanError(f"generated {name}: {str(e).splitlines()[0][:200]}") from None
        print(f"generated {name:9s} tried {tried[0]:8d}  {time.monotonic() - start:7.1f} s  ok")
        total += tried[0]
    return total


def _counted(check, tried: list[int], stop: float):
    """``check`` counting its calls in ``tried[0]``; raises _TimeUp once ``stop`` passed."""
    import time

    def counted(case: object) -> None:
        if time.monotonic() > stop:
            raise _TimeUp
        tried[0] += 1
        check(case)

    return counted


class _TimeUp(BaseException):
    """The --seconds budget of one generated case is spent (not a failure)."""
