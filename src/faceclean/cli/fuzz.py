"""``faceclean fuzz [--target NAME] [--examples N | --seconds S] [--seed K]``: the long
fuzz run.

Feeds every file reader, relay decoder, the page's messages and the pairs reader (or one)
arbitrary and mutated real inputs
(faceclean.evaluation.fuzz: a seeded numpy mutation fuzzer, no hypothesis) and prints,
per target, how many inputs were tried, accepted and refused. Exit 0 when nothing broke
the policy, 1 with the (shrunk) failure and its input otherwise. The structure-aware
generated cases are a dev test: ``FACECLEAN_GENERATED_EXAMPLES=N pytest
tests/test_generated.py`` runs them long.
"""

from __future__ import annotations

import argparse

HELP = "fuzz the readers, relay decoders, page messages and pair folders (seeded mutations)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from faceclean.evaluation.fuzz import TARGETS

    p.add_argument("--target", choices=TARGETS, action="append", help="repeatable (default: all)")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--examples", type=int, metavar="N", help="inputs per target")
    budget.add_argument("--seconds", type=float, metavar="S", help="seconds per target")
    p.add_argument("--seed", type=int, default=0, metavar="K", help="random seed (default 0)")
    p.add_argument("--save", metavar="FILE", help="write a failing input to this file")


def run(args: argparse.Namespace) -> int:
    import sys

    from faceclean.errors import FacecleanError
    from faceclean.evaluation import fuzz
    from faceclean.io.atomic import atomic_write, check_writable

    check_writable(args.save)  # now, not when a failing input turns up
    examples, seconds = args.examples, args.seconds
    if examples is None and seconds is None:
        examples = 10_000
    if (examples is not None and examples < 1) or (seconds is not None and not seconds > 0):
        raise FacecleanError("--examples must be >= 1 and --seconds > 0")
    if examples is not None and examples > 10**9 or seconds is not None and seconds > 1e7:
        raise FacecleanError("--examples at most 1e9, --seconds at most 1e7")
    if not 0 <= args.seed < 2**63:
        raise FacecleanError("--seed must be a whole number from 0 to 2^63 - 1")
    total = 0
    for target in args.target or fuzz.TARGETS:
        report = fuzz.run(
            target,
            examples=examples,
            seconds=seconds,
            seed=args.seed,
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
