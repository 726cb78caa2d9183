"""``faceclean relay --listen URL --send URL``: clean a live face stream between a tracker
and an engine (VMC, Live Link Face UDP, iFacialMocap in; VMC or Live Link out).

Ctrl-C or SIGTERM stops it with exit 0 and a final stats line. See docs/RELAY.md.

Levels before the cleaner (faceclean.adjust): ``--calibration calib.json`` (from
``faceclean calibrate``), ``--set PATTERN.KEY=VALUE`` (gain, offset, curve, clamp, off),
and ``--calibrate-seconds N``: hold a neutral face for the first N seconds of the stream
(no hotkey; frames are relayed meanwhile); from then on each channel's neutral reads 0.
A new stream (the sender restarted) calibrates again on its own first N seconds.
``--record take.csv`` (or .npz) saves what came in to take.csv and what went out to
take.clean.csv when the relay stops: ``faceclean replay take.csv`` streams it again.
``--ui`` serves the tuning page on the running relay (faceclean.ui.live): its controls
change the cleaner between two frames; with it, ``--calibrate-seconds N`` is the page's
Calibrate pressed at start (once, not again on a new stream).
Head and eye rotation (Live Link's 9 angles, VMC's Head/LeftEye/RightEye bones,
iFacialMocap's head and eyes) are cleaned by the rotation filter (``--set
head.min_cutoff=...``); a Live Link stream keeps the tracker's timecode.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from faceclean.cli import options, stopping

if TYPE_CHECKING:
    from faceclean.resolve import Choice

MIN_STATS, MAX_STATS = 0.001, 86400.0  # s, the --stats period
HELP = "clean a live stream: --listen vmc://|livelink://|ifacialmocap:// --send vmc://|livelink://"
EPILOG = (
    options.SETTINGS_HELP
    + """\
levels before the cleaner:
  --calibration calib.json       from 'faceclean calibrate'
  --set 'eyeBlink*.gain=1.2'     per channel, glob or group: gain, offset, curve, clamp, off
  --calibrate-seconds 3          hold a neutral face for the first 3 s of the stream (no
                                 hotkey; frames are relayed meanwhile); a new stream
                                 calibrates again
recording:
  --record session.csv           input to session.csv, cleaned output to session.clean.csv
                                 (or .npz); 'faceclean replay session.csv' streams it again
the tuning page:
  --ui                           serve it (127.0.0.1, a free port, a per-start token; the
                                 URL is printed and opened): sliders, Calibrate, live
                                 faces and curves, settings saved as --preset/--calibration
  --ui-nice 0                    leave the browser's priority as it is (by default a page
                                 that draws on the CPU lets its browser yield to the relay)
"""
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--listen", required=True, metavar="URL", help="e.g. vmc://127.0.0.1:39540")
    p.add_argument("--send", required=True, metavar="URL", help="e.g. vmc://127.0.0.1:39539")
    options.add_arguments(p)
    p.add_argument(
        "--stats", type=float, metavar="SECONDS", help="print counters and latency this often"
    )
    p.add_argument(
        "--calibrate-seconds",
        type=float,
        metavar="N",
        help="calibrate the neutral from the first N seconds of the stream (hold still)",
    )
    p.add_argument(
        "--record",
        metavar="FILE",
        help="save the session: input to FILE, cleaned output to FILE.clean (.csv or .npz)",
    )
    from faceclean.cli import ui

    p.add_argument("--ui", action="store_true", help="serve the tuning page on the relay")
    ui.add_page_arguments(p, "ui-")
    ui.add_nice_argument(p, "the relay")
    ui.add_script_argument(p)


def build_cleaner(choice: Choice) -> tuple[Any, str]:
    """The cleaner the options chose (ARKit-52 channels) and a short description."""
    from faceclean.channels import ARKIT52
    from faceclean.errors import FacecleanError

    if choice.offline:
        raise FacecleanError(f"{choice.source} is offline (non-causal): it cannot run live")
    return choice.build(ARKIT52), choice.source


def with_levels(args: argparse.Namespace, choice: Choice, cleaner: Any) -> tuple[Any, str]:
    """The cleaner behind the level mapping the options ask for, and a note on it."""
    from faceclean.adaptation import unread
    from faceclean.adjust import Adjust, Adjusted
    from faceclean.calibration import LiveCalibration
    from faceclean.channels import ARKIT52

    base = options.calibration(args) or Adjust()
    overrides = choice.adjust(ARKIT52)
    notes = [f"calibration {args.calibration}"] if args.calibration else []
    if why := unread(base, cleaner):  # said, not guessed: the file does nothing here
        notes[-1] += f" ({why}: {choice.source} reads none)"
    notes += [f"{len(overrides.rules)} level overrides"] if overrides.rules else []
    if args.calibrate_seconds is not None:

        def done(adjust: Adjust) -> None:
            if adjust.facts.get("levels") == "none":
                print(f"neutral held: {choice.source} reads this stream's rest itself, no "
                      "levels before it", flush=True)  # fmt: skip
                return
            n = len(adjust.facts.get("channels", {}))
            print(f"calibrated the neutral of {n} channels", flush=True)

        live = LiveCalibration(cleaner, args.calibrate_seconds, base, overrides, on_done=done)
        notes.append(f"neutral from the first {args.calibrate_seconds:g} s")
        return live, "; ".join(notes)
    adjust = base.merged(overrides)
    if not adjust.is_identity:
        cleaner = Adjusted(cleaner, adjust, ARKIT52)
    return cleaner, "; ".join(notes)


def run(args: argparse.Namespace) -> int:
    from faceclean.errors import FacecleanError
    from faceclean.relay import Relay, parse
    from faceclean.relay.recorder import Recorder

    listen, send = parse(args.listen, "listen"), parse(args.send, "send")
    if args.stats is not None and not MIN_STATS <= args.stats <= MAX_STATS:
        raise FacecleanError(
            f"--stats must be between {MIN_STATS:g} and {MAX_STATS:g} seconds (got {args.stats})"
        )
    if args.calibrate_seconds is not None:  # inf: a hold that never ends
        from faceclean.calibration import MAX_NEUTRAL_S as most

        if args.ui:  # the page's own bound
            from faceclean.ui.live import MAX_NEUTRAL as most
        if not 0 < args.calibrate_seconds <= most:
            raise FacecleanError(f"--calibrate-seconds must be over 0 and at most {most:g} "
                                 f"(got {args.calibrate_seconds:g})")  # fmt: skip
    if args.record is not None and not args.record.strip():
        raise FacecleanError("--record: give a file name (.csv or .npz)")
    from faceclean.cli import ui

    ui.check_nice(args)
    script = ui.script(args, args.ui)  # checked before the relay binds
    recorder = Recorder(args.record) if args.record else None
    if args.ui:
        return _with_page(args, listen, send, recorder, script)
    choice = options.choice(args)
    cleaner, what = build_cleaner(choice)
    cleaner, levels = with_levels(args, choice, cleaner)
    check_record(recorder)
    what += f"; levels: {levels}" if levels else ""
    if args.tracker == "mediapipe":  # one warning line if the stream does not look raw
        from faceclean.channels import ARKIT52
        from faceclean.trackers import signature

        def warn(why: str) -> None:
            print(signature.warning(why, "the stream"), file=sys.stderr, flush=True)

        cleaner = signature.Watch(cleaner, ARKIT52, warn)
    from faceclean.channels import POSE

    pose = choice.build_pose(POSE)  # head/eye angles: the rotation filter
    what += f"; head/eye angles: {choice.pose_source}"
    relay = Relay(listen, send, cleaner, recorder=recorder, pose=pose)
    with stopping(relay.stop):  # until the recording is saved: a second signal loses nothing
        with relay:
            stats = _serve(args, relay, send, what)
        return _done(stats, send, recorder)


def _serve(args: argparse.Namespace, relay: Any, send: Any, what: str) -> Any:
    """Run the relay until Ctrl-C or SIGTERM (``stopping``, around it); its stats."""
    listen = relay.listen
    if not _loopback(listen.host):  # said once it listens (a refused start says only why)
        print(
            f"faceclean: warning: listening on {listen.host}: anyone who can reach port "
            f"{relay.address.port} can send faces to this relay (use 127.0.0.1 when the tracker "
            "runs on this machine)",
            file=sys.stderr,
            flush=True,
        )
    print(f"relay {relay.address} -> {send} ({what}); Ctrl-C stops", flush=True)
    return relay.run(args.stats, lambda s: print(f"stats: {s.line()}", flush=True))


def _loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address or name (only this machine can send)."""
    import ipaddress

    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False  # a name: it may resolve to any interface


def check_record(recorder: Any, who: str = "the relay") -> None:
    """--record's files again once the inputs are read (not over a --calibration take or a
    --model: refused only at the end, the session was lost), and what they replace (said
    now: "will replace X when ``who`` stops"). ``track --camera`` calls it too."""
    if recorder is None:
        return
    recorder.check()
    if there := recorder.there():
        print(f"faceclean: warning: --record will replace {' and '.join(map(str, there))} "
              f"when {who} stops", file=sys.stderr, flush=True)  # fmt: skip


def save_record(recorder: Any, first: str = "input") -> str:
    """Save ``recorder``'s two files; the line saying so, each file replaced said so
    (``first``: what the first file holds). ``track --camera`` calls it too."""
    there = recorder.there()
    take, cleaned = recorder.save()
    said = [f"{p} ({what}{', replaced' if p in there else ''})"
            for p, what in ((take, first), (cleaned, "cleaned"))]  # fmt: skip
    return f"recorded {len(recorder)} frames: {', '.join(said)}"


def _done(stats: Any, send: Any, recorder: Any) -> int:
    print(f"stopped: {stats.line()}", flush=True)
    if recorder is not None and len(recorder):
        print(save_record(recorder), flush=True)
    elif recorder is not None:
        print("recorded nothing: no frame was sent, so no file was written", flush=True)
    if stats.send_errors:
        print(f"faceclean: {stats.send_errors} sends refused by {send}", file=sys.stderr)
    return 0


def _with_page(args: argparse.Namespace, listen: Any, send: Any, recorder: Any,
               script: Any = None) -> int:  # fmt: skip
    """The relay with the tuning page on it (faceclean.ui.live)."""
    from faceclean.channels import ARKIT52, POSE
    from faceclean.cli import ui
    from faceclean.relay import Relay
    from faceclean.ui.live import Live, Tap

    tuning = ui.tuning(args).with_choice()
    check_record(recorder)
    tap = Tap(recorder)
    pose = tuning.choice.build_pose(POSE)  # head/eye angles: the rotation filter
    relay = Relay(listen, send, tuning.build(ARKIT52), recorder=tap, pose=pose)
    with stopping(relay.stop):  # until the recordings are saved (the page's, then --record)
        with relay:
            what = f"{relay.address} -> {send}"
            session = Live(tuning, relay, tap, what, nice=args.ui_nice, say=ui.say,
                           script=script)  # fmt: skip
            session.mesh()  # the face built before the page asks
            session.start()
            server = ui.serve(session, args.ui_host, args.ui_port, args.no_browser, "--ui-port")
            try:
                if args.calibrate_seconds is not None:
                    session.handle(None, {"type": "calibrate",
                                          "seconds": args.calibrate_seconds})  # fmt: skip
                stats = _serve(args, relay, send, f"{tuning.choice.source}; tuning page on")
            finally:
                server.close()
                session.stop()
        return _done(stats, send, recorder)
