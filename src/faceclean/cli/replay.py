"""``faceclean replay FILE --send URL``: stream a recorded take as VMC or Live Link packets,
paced by its timestamps, to test a rig without a phone. Ctrl-C or SIGTERM stops it (exit 0).
"""

from __future__ import annotations

import argparse
import signal

HELP = "stream a recorded take (any readable file, or .gesichter) as VMC or Live Link packets"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE", help="take to stream (Live Link CSV, .gesichter, ...)")
    p.add_argument("--send", required=True, metavar="URL", help="vmc://HOST:PORT or livelink://")
    p.add_argument("--speed", type=float, default=1.0, help="playback speed (default 1.0)")
    p.add_argument("--loop", action="store_true", help="repeat until stopped")


def run(args: argparse.Namespace) -> int:
    import threading

    from faceclean.errors import within
    from faceclean.relay import parse
    from faceclean.relay.replay import MAX_SPEED, MIN_SPEED, load_frames, replay

    send = parse(args.send, "send")
    within(args.speed, "--speed", MIN_SPEED, MAX_SPEED)
    frames = load_frames(args.file)
    stop = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        print(
            f"replaying {args.file}: {len(frames)} frames -> {send}"
            + (" (looping; Ctrl-C stops)" if args.loop else ""),
            flush=True,
        )
        sent = replay(frames, send, speed=args.speed, loop=args.loop, stop=stop)
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
    if args.loop or sent == len(frames):
        refused = ""
    elif stop.is_set():
        refused = f" (stopped; {len(frames) - sent} not sent)"
    else:
        refused = f" ({len(frames) - sent} refused: is anything listening at {send}?)"
    print(f"sent {sent} packets{refused}", flush=True)
    return 0
