"""``calibrate --guided --live URL``: prompt in the terminal and record the script's take.

Binds ``URL`` (``vmc://:39540``, ``livelink://:11111``: relay's listen URLs), counts down
``COUNTDOWN`` s, then prints each prompt of the script as its time comes, and records
every face frame (ARKit-52 columns, arrival time, s) from one sender for the script's
length plus ``TAIL`` s. The take goes to the same fit as a file (cli/calibrate_guided.py).
"""

from __future__ import annotations

import select
import socket
import time
from dataclasses import replace

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.guided.script import COUNTDOWN, TAIL

MAX_DATAGRAM = 65536


def record(url: str, script=None, countdown: int = COUNTDOWN, clock=time.monotonic,
           out=print) -> Animation:  # fmt: skip
    """The take recorded from ``url`` while ``script``'s prompts (the shipped script's by
    default) are shown."""
    from faceclean.guided.script import load
    from faceclean.relay import Malformed, parse
    from faceclean.relay.bounds import ArkitColumns

    script = script or load()
    listen = parse(url, "listen")
    family, addr = listen.sockaddr()
    sock = socket.socket(family, socket.SOCK_DGRAM)
    try:
        sock.bind(addr)
    except OSError as e:
        sock.close()
        raise FacecleanError(f"--live {url}: cannot listen ({e.strerror or e})") from None
    sock.setblocking(False)
    listen = replace(listen, port=sock.getsockname()[1])  # port 0: the one the system chose
    decoder, columns, sender = listen.decoder(), ArkitColumns(), None
    times: list[float] = []
    rows: list[np.ndarray] = []
    try:
        out(f"guided calibration: {len(script.prompts)} prompts, {script.seconds:.0f} s; "
            f"listening on {listen}")  # fmt: skip
        for k in range(countdown, 0, -1):
            out(f"  starting in {k}...")
            _drain(sock, 1.0, clock, decoder, None, None, None)
        t0 = clock()
        pending = list(script.prompts)
        end = t0 + script.seconds + TAIL
        while clock() < end:
            now = clock() - t0
            while pending and pending[0].start <= now:
                p = pending.pop(0)
                out(f"  {p.start:5.1f} s  {p.text}")
            sender = _drain(sock, 0.02, clock, decoder, columns, sender, (t0, times, rows))
    except Malformed as e:
        raise FacecleanError(f"--live {url}: {e}") from None
    finally:
        sock.close()
    if len(times) < 2:
        raise FacecleanError(f"--live {url}: no face frames arrived (is the tracker sending?)")
    return Animation(np.asarray(times), np.asarray(rows), ARKIT52, {"format": "live"})


def _drain(sock, wait, clock, decoder, columns, sender, into):
    """Read what arrives within ``wait`` s; append face frames (of the first sender) to
    ``into`` = (t0, times, rows); the sender followed."""
    from faceclean.relay import Malformed

    ready, _, _ = select.select([sock], [], [], wait)
    if not ready:
        return sender
    while True:
        try:
            data, who = sock.recvfrom(MAX_DATAGRAM)
        except (BlockingIOError, InterruptedError):
            return sender
        except OSError:
            continue
        if into is None:
            continue  # the countdown: frames are not kept
        try:
            frame = decoder.feed(data)
        except Malformed:
            continue
        if frame is None or not frame.is_face or (sender is not None and who != sender):
            continue
        sender = who
        cols, have = columns(tuple(frame.names))
        row = np.full(len(ARKIT52), np.nan)
        row[have] = np.asarray(frame.values, dtype=np.float64)[cols]
        t0, times, rows = into
        times.append(clock() - t0)
        rows.append(row)
