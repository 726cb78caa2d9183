"""Replay a recorded take as a live stream (VMC or Live Link packets), paced by its times.

A take is any file ``faceclean.io.load`` reads, or a ``.gesichter`` recording of Live Link
packets. Sent times start at 0 on the first frame; with ``loop`` each pass goes on from
where the last ended (times keep increasing, as from a live tracker). Missing frames
(tracking loss) send nothing, as a tracker that lost the face.

Timecode (Live Link output): a ``.gesichter`` recording's packets keep their own frame
number, sub-frame and rate; a take with a timecode (a Live Link CSV's, or any file's
``timecode_start``) sends that timecode at 60 fps frames (the CSV's own rate); each
further ``loop`` pass goes on from the end of the last at the same rate. Only a take
without one starts at frame 0.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError, within
from faceclean.relay import livelink, vmc
from faceclean.relay.frame import POSE_NAMES, Frame, Malformed
from faceclean.relay.url import Endpoint
from faceclean.timing import Restarts

MIN_SPEED, MAX_SPEED = 1e-3, 1e3  # --speed: playback rate bounds
MAX_PAUSE = 600.0  # s between two frames: a longer one is a broken clock, not a pause


def frames_from_animation(anim: Animation) -> list[Frame]:
    """The valid frames of a take: its ARKit channels (camelCase), times, Live Link angles."""
    values, present = anim.arkit()  # (N, 52)
    names = tuple(n for n, p in zip(ARKIT52, present, strict=True) if p)
    if not names:
        raise FacecleanError("replay: the take has no ARKit blendshape channels")
    pose = _pose(anim)
    t0 = float(anim.times[anim.valid][0]) if anim.valid.any() else 0.0
    start = anim.meta.get("timecode_start")
    return [
        Frame(
            names,
            values[i, present],
            float(anim.times[i] - t0),
            None if pose is None else pose[i],
            timecode=None if start is None else livelink.timecode_at(start + anim.times[i]),
        )
        for i in np.flatnonzero(anim.valid)
    ]


def _pose(anim: Animation) -> np.ndarray | None:
    """(N, 9) Live Link angles from ``meta["pose"]`` (Live Link CSV), or None."""
    pose, pose_names = anim.meta.get("pose"), anim.meta.get("pose_names")
    if pose is None or pose_names is None:
        return None
    cols = {str(n).lower(): j for j, n in enumerate(pose_names)}
    out = np.zeros((anim.n_frames, len(POSE_NAMES)))
    for i, n in enumerate(POSE_NAMES):
        if n.lower() in cols:
            out[:, i] = np.asarray(pose, np.float64)[:, cols[n.lower()]]
    return np.nan_to_num(out)


def frames_from_recording(path: str | os.PathLike) -> list[Frame]:
    """The frames of a ``.gesichter`` Live Link recording, times from 0."""
    frames = []
    for packet in livelink.read_recording(path):
        try:
            frames.append(livelink.decode(packet))
        except Malformed as e:
            raise FacecleanError(f"{Path(path).name}: {e}") from None
    timed = [f.t for f in frames if f.t is not None]
    t0 = min(timed) if timed else 0.0
    return [replace(f, t=None if f.t is None else f.t - t0) for f in frames]


def load_frames(path: str | os.PathLike) -> list[Frame]:
    """Frames of any take ``faceclean.io.load`` reads, or of a ``.gesichter`` recording."""
    if Path(path).suffix.lower() == ".gesichter":
        frames = frames_from_recording(path)
    else:
        from faceclean.io import load

        frames = frames_from_animation(load(path))
    if not frames:
        raise FacecleanError(f"{Path(path).name}: no frames to replay")
    t = np.array([f.t for f in frames if f.t is not None], dtype=np.float64)
    t = t[np.isfinite(t)]
    Restarts(Path(path).name).see(t)  # times that stand still would go unpaced: as clean
    jumps = np.flatnonzero(np.diff(t) > MAX_PAUSE)
    if len(jumps):  # replay waits out each pause in real time
        i = int(jumps[0])
        raise FacecleanError(f"{Path(path).name}: the times jump {t[i + 1] - t[i]:.4g} s at "
                             f"{t[i]:.3f} s, and replay would wait that long: cut the take "
                             "there, or fix its times")  # fmt: skip
    return frames


def _period(frames: list[Frame]) -> float:
    """Median frame period, s (1/60 when unknown)."""
    t = np.array([f.t for f in frames if f.t is not None])
    dt = np.diff(t)
    dt = dt[dt > 0]
    return float(np.median(dt)) if len(dt) else 1.0 / 60.0


def _later(timecode, seconds: float):
    """``timecode`` (frame number, sub-frame, num, den) ``seconds`` later at its rate."""
    if timecode is None or seconds == 0:
        return timecode
    number, sub, num, den = timecode
    return livelink.timecode_at((number + sub) * den / num + seconds, (num, den))


def replay(
    frames: list[Frame],
    send: Endpoint,
    *,
    speed: float = 1.0,
    loop: bool = False,
    stop: threading.Event | None = None,
    clock: Callable[[], float] = time.monotonic,
    wait: Callable[[float], None] | None = None,
) -> int:
    """Send ``frames`` to ``send`` paced by their times / ``speed``; the number sent.

    ``wait(deadline)`` blocks until ``clock()`` reaches ``deadline`` (default: waits on
    ``stop``, so setting it ends the replay at once). ``loop`` repeats until ``stop``.
    """
    within(speed, "replay: --speed", MIN_SPEED, MAX_SPEED)  # 1e-300 would wait forever
    stop = stop or threading.Event()
    if wait is None:

        def wait(deadline: float) -> None:
            stop.wait(max(0.0, deadline - clock()))

    if send.scheme == "vmc":
        encoder = vmc.Encoder(names=send.options.get("names", "keep"), stamp=True)
    else:
        encoder = send.encoder()
    family, addr = send.sockaddr()
    period = _period(frames)
    times = np.array([np.nan if f.t is None else f.t for f in frames])
    times = np.where(np.isfinite(times), times, np.arange(len(frames)) * period)
    cycle = float(times[-1] - times[0]) + period  # s, one pass
    sent = 0
    with socket.socket(family, socket.SOCK_DGRAM) as sock:
        try:
            sock.connect(addr)
        except OSError as e:  # a broadcast address (no SO_BROADCAST), no route
            why = e.strerror or e
            raise FacecleanError(f"cannot send to {addr[0]} port {addr[1]}: {why} "
                                 "(give a host's address)") from None  # fmt: skip
        start = clock()
        k = 0
        while not stop.is_set():
            for frame, t in zip(frames, times, strict=True):
                t = float(t) + k * cycle  # s, sender time of this pass
                wait(start + (t - times[0]) / speed)
                if stop.is_set():
                    break
                timecode = _later(frame.timecode, k * cycle)
                try:
                    sock.send(encoder.encode(replace(frame, t=t, timecode=timecode)))
                    sent += 1
                except OSError:  # no listener yet: a live tracker does not care either
                    pass
            k += 1
            if not loop:
                break
    return sent
