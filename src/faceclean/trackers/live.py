"""Live: a camera's frames tracked, cleaned and sent on, as the relay sends.

``Live(camera, tracker, cleaner, send)`` takes the camera's newest frame (never a queue:
a loop that falls behind skips frames, and the camera counts them as dropped), tracks it
at its capture time (``tracker``: a faceclean.tracking ``Tracker`` whose ``names`` are
ARKit channels, trackers/face.py's ``FaceTracker`` for ``track --camera``), cleans the 52
scores (``cleaner.step``) and the head angles (``pose.step``, the rotation filter; a
tracker without ``pose`` leaves them NaN), and sends one datagram to ``send`` (VMC or Live
Link, the relay's encoders). A lost face is a missing frame for the cleaner (it holds);
nothing is sent before the first face. ``run()`` serves until ``stop()`` or until the
camera ends; ``stats`` counts frames and times what the loop adds to MediaPipe.
``swap(cleaner)`` hands the loop another cleaner, taken between two frames (the relay's
rule, relay/loop.py); ``on_image(rgb, t)``, when set, is given each frame before it is
tracked (the tuning page keeps a reference: it must return at once).
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from faceclean.channels import ARKIT52, POSE
from faceclean.errors import FacecleanError
from faceclean.relay.frame import Frame
from faceclean.relay.url import Endpoint

WINDOW = 8192  # timing samples kept for the percentiles


@dataclass
class Stats:
    """Counters of one live run; times in ns over the last WINDOW frames."""

    captured: int = 0  # frames the camera delivered
    dropped: int = 0  # camera frames replaced before the loop took them
    tracked: int = 0  # frames given to MediaPipe
    lost: int = 0  # of those, frames without a face
    sent: int = 0
    send_errors: int = 0
    track_ns: list[int] = field(default_factory=list)  # MediaPipe, per frame
    added_ns: list[int] = field(default_factory=list)  # cleaning + encoding + sending

    def timed(self, track: int, added: int) -> None:
        for samples, ns in ((self.track_ns, track), (self.added_ns, added)):
            samples.append(ns)
            if len(samples) > WINDOW:
                del samples[: len(samples) - WINDOW]

    def line(self) -> str:
        def ms(samples: list[int], q: float) -> str:
            return f"{np.percentile(samples, q) / 1e6:.2f}" if samples else "-"

        return (
            f"camera {self.captured} dropped {self.dropped} tracked {self.tracked} "
            f"lost {self.lost} sent {self.sent}; MediaPipe p50 {ms(self.track_ns, 50)} ms, "
            f"clean+send p50 {ms(self.added_ns, 50)} p99 {ms(self.added_ns, 99)} ms"
        )


class Live:
    """One live session (see the module docstring)."""

    def __init__(self, camera, tracker, cleaner, send: Endpoint, *, pose=None, recorder=None,
                 clock: Callable[[], int] = time.perf_counter_ns) -> None:  # fmt: skip
        self.camera, self.tracker, self.cleaner, self.pose = camera, tracker, cleaner, pose
        self.send, self.recorder, self.clock = send, recorder, clock
        self.stats = Stats()
        self._cols = np.array([ARKIT52.index(n) for n in tracker.names])  # -> ARKit-52 columns
        self.encoder = send.encoder()
        self._stopping = False
        self._seen = False  # a face has been found: from then on every frame is sent
        self._pending = None  # handed over by swap(), taken between frames
        self._swap_lock = threading.Lock()
        self.on_image: Callable[[np.ndarray, float], None] | None = None
        family, addr = send.sockaddr()
        self._out = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._out.connect(addr)
        except OSError as e:
            self._out.close()
            raise FacecleanError(f"cannot send to {send}: {e.strerror or e}") from None

    def swap(self, cleaner) -> None:
        """Clean with ``cleaner`` from the next frame on (thread-safe; warmed up and probed
        by the caller, as for the relay)."""
        with self._swap_lock:
            self._pending = cleaner

    def stop(self) -> None:
        """Ask ``run`` to return (thread- and signal-safe)."""
        self._stopping = True

    @property
    def stopped(self) -> bool:
        """Whether ``stop()`` ended the run (not the camera's end)."""
        return self._stopping

    def run(self, every: float | None = None, on_stats: Callable[[Stats], None] | None = None,
            ) -> Stats:  # fmt: skip
        """Serve until ``stop()`` or the camera's end; ``on_stats`` every ``every`` s."""
        next_stats = time.monotonic() + every if every else None
        while not self._stopping:
            got = self.camera.latest(timeout=0.2)
            if got is not None:
                self._frame(*got)
            elif self.camera.ended:
                break
            if next_stats is not None and time.monotonic() >= next_stats:
                if on_stats is not None:
                    on_stats(self._counted())
                next_stats = max(next_stats + every, time.monotonic())
        return self._counted()

    def _counted(self) -> Stats:
        self.stats.captured, self.stats.dropped = self.camera.captured, self.camera.dropped
        return self.stats

    def _frame(self, rgb: np.ndarray, t: float) -> None:
        if self.on_image is not None:
            self.on_image(rgb, t)
        if self._pending is not None:
            with self._swap_lock:
                self.cleaner, self._pending = self._pending, None
        start = self.clock()
        found = self.tracker.read(rgb, t)
        tracked = self.clock()
        self.stats.tracked += 1
        x = np.full(len(ARKIT52), np.nan)  # (52,) canonical order; a lost face: all NaN
        head = np.full(len(POSE), np.nan)  # (9,) rad; the eyes are not tracked
        if found is None:
            self.stats.lost += 1
        else:
            x[self._cols] = found.scores
            if found.pose is not None:
                head[:3] = found.pose
            self._seen = True
        y = np.asarray(self.cleaner.step(x, t), np.float64)  # (52,)
        pose = head
        if self.pose is not None:  # a lost face holds the angles, as it holds the scores
            cleaned = np.asarray(self.pose.step(head, t), np.float64)
            pose = np.where(np.isnan(cleaned), head, cleaned)
        if not self._seen or np.isnan(y).all():
            return
        out = Frame(ARKIT52, np.nan_to_num(y), t, pose)  # NaN eyes: the encoders leave them
        try:
            self._out.send(self.encoder.encode(out))
            self.stats.sent += 1
        except OSError:  # no listener yet (ICMP refused), a full buffer
            self.stats.send_errors += 1
        self.stats.timed(tracked - start, self.clock() - tracked)
        if self.recorder is not None:
            self.recorder.add(t, x, y, head, pose)

    def close(self) -> None:
        self._out.close()

    def __enter__(self) -> Live:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
