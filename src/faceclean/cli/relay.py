"""``faceclean relay --listen URL --send URL``: clean a live face stream between a tracker
and an engine (VMC, Live Link Face UDP, iFacialMocap in; VMC or Live Link out).

Ctrl-C or SIGTERM stops it with exit 0 and a final stats line. See docs/RELAY.md.
"""

from __future__ import annotations

import argparse
import signal
import sys
from typing import Any

HELP = "clean a live stream: --listen vmc://|livelink://|ifacialmocap:// --send vmc://|livelink://"


def add_cleaner_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--method", help="cleaner by name (default: the shipped default cleaner)")
    p.add_argument(
        "--set",
        dest="params",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        help="cleaner parameter for --method, repeatable",
    )
    p.add_argument("--model", metavar="FILE", help="learned model file (.npz)")
    p.add_argument("--preset", metavar="FILE", help="preset file made by 'faceclean tune'")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--listen", required=True, metavar="URL", help="e.g. vmc://127.0.0.1:39540")
    p.add_argument("--send", required=True, metavar="URL", help="e.g. vmc://127.0.0.1:39539")
    add_cleaner_arguments(p)
    p.add_argument(
        "--stats", type=float, metavar="SECONDS", help="print counters and latency this often"
    )


def build_cleaner(args: argparse.Namespace) -> tuple[Any, str]:
    """The cleaner the options ask for (ARKit-52 channels) and a short description."""
    from faceclean import filters
    from faceclean.channels import ARKIT52
    from faceclean.cli.clean import parse_params
    from faceclean.errors import FacecleanError

    given = [o for o in ("method", "model", "preset") if getattr(args, o)]
    if len(given) > 1:
        raise FacecleanError(f"give one of --method, --model, --preset (got {', '.join(given)})")
    if args.params and not args.method:
        raise FacecleanError("--set needs --method")
    if args.method:
        params = parse_params(args.params)
        if filters.cleaner_class(args.method).offline:
            raise FacecleanError(f"{args.method} is offline (non-causal): it cannot run live")
        return filters.make(args.method, params, names=ARKIT52), args.method
    from faceclean.cleaner import Cleaner

    cleaner = Cleaner.load(args.model or args.preset)  # None: the shipped default
    if cleaner.offline:
        raise FacecleanError(f"{cleaner.source} is offline (non-causal): it cannot run live")
    return cleaner, cleaner.source + (f"; {cleaner.note}" if cleaner.note else "")


def run(args: argparse.Namespace) -> int:
    from faceclean.errors import FacecleanError
    from faceclean.relay import Relay, parse

    listen, send = parse(args.listen, "listen"), parse(args.send, "send")
    if args.stats is not None and not args.stats > 0:
        raise FacecleanError(f"--stats must be > 0 seconds (got {args.stats})")
    cleaner, what = build_cleaner(args)
    with Relay(listen, send, cleaner) as relay:

        def stop(signum: int, frame: object) -> None:
            relay.stop()

        old = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            print(f"relay {relay.address} -> {send} ({what}); Ctrl-C stops", flush=True)
            stats = relay.run(args.stats, lambda s: print(f"stats: {s.line()}", flush=True))
        finally:
            for s, handler in old.items():
                signal.signal(s, handler)
    print(f"stopped: {stats.line()}", flush=True)
    if stats.send_errors:
        print(f"faceclean: {stats.send_errors} sends refused by {send}", file=sys.stderr)
    return 0
