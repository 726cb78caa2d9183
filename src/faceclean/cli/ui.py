"""``faceclean ui take.csv``: the tuning page on a recorded take (``relay --ui`` is live).

Serves the page on 127.0.0.1 (``--host`` to change; ``--port``, else a free one), prints
its URL with the per-start token and opens it in a browser when one is there. The page
takes the cleaner options of ``clean`` as its starting point; its controls are the same
words (``--method``, ``--set``, ``--calibration``), saved as the files the CLI reads.
Ctrl-C stops it. See faceclean.ui. ``camera_page`` serves the same page on ``track
--camera --ui`` (faceclean.ui.camera); ``say`` prints what a page has to say.
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator
from typing import Any

from faceclean.cli import options

HELP = "tune a take in the browser: sliders, calibrate, curves and faces; save settings"
NICE = 10  # a page drawn on the CPU lets its browser yield at this nice (--ui-nice's default)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("take", metavar="TAKE", help="the take to tune on (any format clean reads)")
    options.add_arguments(p, "the cleaner to start from")
    add_page_arguments(p)
    add_script_argument(p)


def add_page_arguments(p: argparse.ArgumentParser, prefix: str = "") -> None:
    """--host/--port/--no-browser (``relay`` names them --ui-host, --ui-port)."""
    p.add_argument(
        f"--{prefix}host",
        default="127.0.0.1",
        metavar="HOST",
        help="address the page listens on (default 127.0.0.1, loopback only)",
    )
    p.add_argument(
        f"--{prefix}port", type=int, default=0, metavar="PORT", help="port (default: a free one)"
    )
    p.add_argument("--no-browser", action="store_true", help="print the URL, open no browser")


def add_nice_argument(p: Any, loop: str) -> None:
    """--ui-nice (relay, track --camera): how far a page drawn on the CPU yields."""
    p.add_argument(
        "--ui-nice",
        type=int,
        default=NICE,
        metavar="N",
        help=f"when the page draws on the CPU (no GPU), its browser yields to {loop} at this "
        f"nice, 1-19 (Linux: its sessions' autogroups, else each of its threads; default {NICE}; "
        "0: leave it)",
    )


def add_script_argument(p: Any, what: str = "the page's guided calibration") -> None:
    """--script FILE (calibrate --guided, ui, relay --ui, track --camera --ui)."""
    p.add_argument(
        "--script",
        metavar="FILE",
        help=f"{what}: a guided script of your own (shorter, in your performers' language; "
        "start from `faceclean calibrate --print-script json`) instead of the shipped one",
    )


def script(args: argparse.Namespace, ui: bool = True):
    """The guided script ``--script`` names (checked: one line if bad), None for the
    shipped one; refused where no page or guided calibration would use it."""
    from faceclean.errors import FacecleanError
    from faceclean.guided.script import load

    if getattr(args, "script", None) is None:
        return None
    if not ui:
        raise FacecleanError("--script is the page's guided script: give it with --ui")
    return load(args.script)


def check_nice(args: argparse.Namespace) -> int:
    from faceclean.errors import FacecleanError
    from faceclean.ui.priority import MAX_NICE

    if not 0 <= args.ui_nice <= MAX_NICE:
        raise FacecleanError(f"--ui-nice must be in 0..{MAX_NICE} (got {args.ui_nice})")
    return args.ui_nice


def tuning(args: argparse.Namespace):
    """The page's starting state: the options, as the CLI reads them."""
    from faceclean.ui.tuning import Tuning

    calibration = options.calibration(args)
    words = options.words(args)  # checked as the CLI checks them
    tracker = getattr(args, "tracker", None)
    if not any(getattr(args, o, None) for o in ("method", "model", "preset")):
        words = None  # the tracker's shipped cleaner, named as --tracker on the page
    return Tuning(words, tuple(args.params), calibration, args.calibration, tracker)


def serve(session, host: str, port: int, no_browser: bool, flag: str = "--port"):
    """The started server, its URL printed (and opened in a browser unless told not to)."""
    from faceclean.errors import FacecleanError
    from faceclean.ui.server import Server

    if not 0 <= port <= 65535:
        raise FacecleanError(f"{flag} must be in 0..65535 (got {port})")
    server = Server(session, host, port).start()
    print(f"tuning page: {server.url}", flush=True)
    if host not in ("127.0.0.1", "localhost", "::1"):
        print(f"faceclean: the page listens on {host}: anyone with the URL can use it", flush=True)
    if not no_browser:
        import webbrowser

        with contextlib.suppress(Exception):  # no browser here: the printed URL is enough
            webbrowser.open(server.url)
    return server


def say(line: str) -> None:
    """What the page has to say, printed (faceclean.ui prints nothing itself)."""
    print(line, flush=True)


@contextlib.contextmanager
def camera_page(args: argparse.Namespace, loop: Any, camera: Any, tap: Any,
                script: Any = None) -> Iterator[Any]:  # fmt: skip
    """``track --camera --ui``: the page on the camera loop (faceclean.ui.camera) while the
    block runs; nothing without a ``tap`` (no --ui). ``script``: ``--script``'s, loaded."""
    if tap is None:
        yield None
        return
    from faceclean.ui.camera import CameraPage

    session = CameraPage(tuning(args).with_choice(), loop, camera, tap, f"camera {args.camera}",
                         nice=check_nice(args), say=say, script=script)  # fmt: skip
    session.mesh()  # the face built before the page asks
    loop.on_image = session.image
    session.start()
    try:
        server = serve(session, args.ui_host, args.ui_port, args.no_browser)
        try:
            yield session
        finally:
            server.close()
    finally:
        loop.on_image = None
        session.stop()


def run(args: argparse.Namespace) -> int:
    import threading

    from faceclean.ui.offline import Offline

    session = Offline(args.take, tuning(args), script(args))
    session.mesh()  # the face built before the page asks
    server = serve(session, args.host, args.port, args.no_browser)
    try:
        threading.Event().wait()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    print("stopped", flush=True)
    return 0
