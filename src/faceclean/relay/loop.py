"""The relay's socket loop: receive, decode, clean, encode, send; newest frame only.

Per wake-up the socket is drained without blocking; of the face frames it held, only the
newest is cleaned and sent (never a queue: a relay that falls behind skips, it does not
lag). It follows one sender's face: another sender's face frames are taken only after the
followed one has been silent for ``HANDOVER`` s *and* the other has streamed for ``CLAIM``
s (frames under ``CLAIM`` s apart), longest of the live streams, so a stray frame never
takes the stream and senders that appear and vanish never keep it, while a tracker
restarted on a new port takes over within about a second. Datagrams that carry
only passthrough messages are forwarded as they come (VMC output). Ordering: a frame
whose time is not after the last one sent is dropped (out of order or duplicate); a
backwards jump over ``RESTART`` seconds is a new stream (the sender restarted) and
restarts the cleaner. Frames without a timestamp, and the handover, take their arrival
time (``clock``, time.monotonic by default). A long silence
restarts the cleaner through its own ``max_gap`` rule (filters/base.py), so the face does
not jump or drift when it returns. The loop sends only to the ``send`` endpoint, never
back to a sender. Decoder state is kept per source address and every sender-driven cache
is bounded (relay/bounds.py); a datagram from the relay's own sending socket (``--send``
looping back to ``--listen``) is dropped and counted, never relayed again.

No dropped start: the cleaner is warmed up (``warm_up``: a few frames through every path
of its step, then ``reset()``) before the socket is bound, so the first packets meet a
ready cleaner instead of queueing behind a just-in-time compile (the shipped model's
numba kernel compiles on its first advancing step). A ``Recorder`` given to the relay
keeps every cleaned frame (relay/recorder.py). ``swap(cleaner)`` hands the loop another
cleaner from any thread (the tuning page, faceclean.ui.live): it is taken between two
frames, so no frame is lost or cleaned twice; warming it up and probing it is the caller's.

Head pose: a frame's 9 head/eye angles (Live Link, a VMC Head/eye bone, iFacialMocap's
head) go through ``pose`` (the rotation filter, filters/rotation.py) at the frame's time;
a frame without a single finite blendshape is tracking loss for the angles too (they
hold), and an angle the source did not send stays absent. The sender's timecode (Live
Link frame number, sub-frame and rate) goes out with the frame unchanged.
"""

from __future__ import annotations

import contextlib
import select
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.relay import bounds
from faceclean.relay.frame import Decoder, Frame, Malformed
from faceclean.relay.recorder import Recorder
from faceclean.relay.url import Endpoint

RESTART = 1.0  # s; a backwards jump in sender time larger than this is a new stream
MAX_DATAGRAM = 65535  # bytes
MAX_DRAIN = 256  # datagrams read per wake-up before the newest frame is processed
WINDOW = 8192  # latency samples kept for the percentiles
RCVBUF = 1 << 20  # bytes asked for the receive buffer (the kernel may cap it)
HANDOVER = 1.0  # s the followed sender must be silent before another sender's face is taken
CLAIM = 0.25  # s another sender must stream (frames under CLAIM s apart) to take over


class Stepper(Protocol):
    """Any streaming cleaner: ``filters`` cleaners and the ``faceclean.Cleaner`` facade."""

    def reset(self) -> None: ...

    def step(self, frame: np.ndarray, t: float) -> np.ndarray: ...


@dataclass
class Stats:
    """Counters of one relay run. Latency: receive to send, ns, over the last WINDOW frames."""

    datagrams: int = 0
    frames_in: int = 0  # face frames decoded
    frames_out: int = 0  # face frames sent
    passthrough: int = 0  # passthrough-only datagrams forwarded
    out_of_order: int = 0  # not after the last frame sent (late or duplicate)
    stale: int = 0  # superseded by a newer frame in the same drain
    malformed: int = 0  # datagrams that are not packets of the protocol
    missing: int = 0  # frames without a single finite value (tracking loss)
    restarts: int = 0  # sender time jumped back over RESTART s
    send_errors: int = 0  # sends the OS refused (no listener, ...)
    own: int = 0  # datagrams from the relay's own sending socket (a loop), dropped
    foreign: int = 0  # face frames from a second sender while the first one streams
    latency_ns: np.ndarray = field(default_factory=lambda: np.zeros(WINDOW, np.int64))
    n_latency: int = 0

    @property
    def dropped(self) -> int:
        return self.out_of_order + self.stale

    def record(self, ns: int) -> None:
        self.latency_ns[self.n_latency % WINDOW] = ns
        self.n_latency += 1

    def latencies_ms(self) -> np.ndarray:
        """The kept latency samples (up to WINDOW), ms."""
        return self.latency_ns[: min(self.n_latency, WINDOW)] / 1e6

    def percentile_ms(self, q: float) -> float:
        lat = self.latencies_ms()
        return float(np.percentile(lat, q)) if len(lat) else float("nan")

    def line(self) -> str:
        """One human line: frames in/out, dropped, malformed, latency p50/p99."""
        return (
            f"in {self.frames_in} out {self.frames_out} "
            f"dropped {self.dropped} (order {self.out_of_order}, stale {self.stale}) "
            f"malformed {self.malformed} passthrough {self.passthrough} "
            f"foreign {self.foreign} own {self.own} " + self._latency()
        )

    def _latency(self) -> str:
        if not self.n_latency:  # an idle relay has no latency to show, not "nan ms"
            return "latency - (no frames sent yet)"
        return f"latency p50 {self.percentile_ms(50):.3f} ms p99 {self.percentile_ms(99):.3f} ms"


def warm_up(cleaner: Stepper, frames: int = 6) -> None:
    """Step ``cleaner`` through its first-frame, advancing and missing-value paths on
    (52,) frames at 60 fps, then ``reset()`` it: whatever it compiles or allocates on
    first use happens now, not on the first packets; a cleaner that answers finite
    frames with NaN or inf (a broken model) is refused. A cleaner with a ``warm_up()``
    method (one whose steps have effects beyond its state) is asked to do it itself."""
    own = getattr(cleaner, "warm_up", None)
    if callable(own):  # a cleaner with side effects warms up in its own way
        own()
        return
    rng = np.random.default_rng(0)
    for i in range(frames):
        x = rng.uniform(0.0, 0.5, len(ARKIT52))
        if i == frames - 2:
            x[::3] = np.nan  # some channels missing
        if i == frames - 1:
            x[:] = np.nan  # a missing frame
        y = np.asarray(cleaner.step(x, i / 60.0), dtype=np.float64)
        if not np.isfinite(y).all():  # finite weights in must give finite weights out
            raise FacecleanError(
                "the cleaner turns finite input into NaN or inf (a broken model file?)"
            )
    cleaner.reset()


class Relay:
    """A bound relay: ``run()`` serves until ``stop()`` (thread- and signal-safe)."""

    def __init__(
        self,
        listen: Endpoint,
        send: Endpoint,
        cleaner: Stepper,
        *,
        clock: Callable[[], float] = time.monotonic,
        recorder: Recorder | None = None,
        pose: Stepper | None = None,
    ) -> None:
        self.listen, self.send, self.cleaner, self.clock = listen, send, cleaner, clock
        self.recorder = recorder
        self.pose = pose  # the head/eye angles' cleaner ((9,) frames), or None: as received
        warm_up(cleaner)  # before the socket exists: nothing queues behind it
        probe(cleaner)  # a cleaner that erases the face does not start
        self._decoders: bounds.Bounded[object, Decoder] = bounds.Bounded(bounds.MAX_SENDERS)
        self.encoder = send.encoder()
        self.stats = Stats()
        self._vmc_out = send.scheme == "vmc"
        self._columns = bounds.ArkitColumns()  # a frame's names -> its ARKit columns
        self._last_t: float | None = None  # s, time of the last frame sent
        self._packet_clock: bool | None = None  # the stream's frames carry their time
        self._source: object = None  # address of the sender whose face is followed
        self._source_seen = -float("inf")  # clock() of its last face frame
        # other senders' face streams: sender -> (streaming since, last frame) s
        self._claims: bounds.Bounded[object, tuple[float, float]] = bounds.Bounded(
            bounds.MAX_SENDERS
        )
        self._stopping = False
        self._pending: Stepper | None = None  # handed over by swap(), taken between frames
        self._swap_lock = threading.Lock()
        family, addr = listen.sockaddr()
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            with contextlib.suppress(OSError):
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF)
            self._sock.bind(addr)
            self._sock.setblocking(False)
            out_family, out_addr = send.sockaddr()
            self._out = socket.socket(out_family, socket.SOCK_DGRAM)
            self._out.connect(out_addr)  # the one address we ever send to
            self._own = self._out.getsockname()  # datagrams from here are our own output
            if _same_socket(out_addr, self._sock.getsockname()):
                self._out.close()
                raise FacecleanError(
                    f"--send {send} is the address the relay listens on: "
                    "every datagram would come back to it"
                )
        except OSError as e:
            self._sock.close()
            raise FacecleanError(f"cannot relay {listen} -> {send}: {e.strerror or e}") from None
        except FacecleanError:
            self._sock.close()
            raise
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)

    @property
    def address(self) -> Endpoint:
        """The listening endpoint with its actual port (after binding port 0)."""
        host, port = self._sock.getsockname()[:2]
        return Endpoint(self.listen.scheme, host, port, self.listen.options)

    @property
    def sender(self) -> object:
        """The address of the sender whose face is followed (None before the first)."""
        return self._source

    def swap(self, cleaner: Stepper) -> None:
        """Clean with ``cleaner`` from the next frame on (thread-safe; see the module
        docstring). Warm it up (``warm_up``) and ``probe`` it before: the loop does not."""
        with self._swap_lock:
            self._pending = cleaner

    def stop(self) -> None:
        """Ask ``run`` to return; safe from another thread or a signal handler."""
        self._stopping = True
        with contextlib.suppress(OSError):
            self._wake_w.send(b"\x00")

    def close(self) -> None:
        for s in (self._sock, self._out, self._wake_r, self._wake_w):
            s.close()

    def __enter__(self) -> Relay:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def run(
        self,
        stats_every: float | None = None,
        on_stats: Callable[[Stats], None] | None = None,
    ) -> Stats:
        """Serve until ``stop()``; every ``stats_every`` s call ``on_stats(stats)``."""
        watch = [self._sock, self._wake_r]
        next_stats = time.monotonic() + stats_every if stats_every else None
        while not self._stopping:
            timeout = None if next_stats is None else max(0.0, next_stats - time.monotonic())
            ready, _, _ = select.select(watch, [], [], timeout)
            if self._stopping:
                break
            if self._sock in ready:
                self._drain()
            if next_stats is not None and time.monotonic() >= next_stats:
                if on_stats is not None:
                    on_stats(self.stats)
                next_stats = max(next_stats + stats_every, time.monotonic())
        return self.stats

    def _drain(self) -> None:
        """Read what is waiting; process the newest good face frame among it."""
        best: tuple[Frame, float, int] | None = None  # (frame, time s, receive ns)
        best_t = self._last_t
        for _ in range(MAX_DRAIN):
            try:
                data, sender = self._sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # e.g. an ICMP error queued on the socket
                continue
            received = time.perf_counter_ns()
            self.stats.datagrams += 1
            if sender == self._own:  # our own output came back: never relay it again
                self.stats.own += 1
                continue
            decoder = self._decoders.get(sender) or self._decoders.put(
                sender, self.listen.decoder()
            )
            try:
                frame = decoder.feed(data)
            except Malformed:
                self.stats.malformed += 1
                continue
            if frame is None:
                continue
            if not frame.is_face:
                if self._vmc_out:
                    self.stats.passthrough += 1
                    data = self.encoder.encode(frame)
                    if data:  # b"": nothing finite was left to forward
                        self._send(data)
                continue
            heard = self.clock()
            if sender != self._source and not self._takes_over(sender, heard):
                self.stats.foreign += 1  # one face at a time: another sender is not mixed in
                continue
            self._source, self._source_seen = sender, heard
            self.stats.frames_in += 1
            packet = frame.t is not None
            t = frame.t if packet else self.clock()
            if packet != self._packet_clock:  # the time base changed: a new stream
                self._packet_clock = packet
                best_t = self._last_t = None
                self._reset()
            elif best_t is not None and t <= best_t:
                if best_t - t <= RESTART:
                    self.stats.out_of_order += 1
                    continue
                self.stats.restarts += 1
                self._reset()
            if best is not None:
                self.stats.stale += 1
            best, best_t = (frame, t, received), t
        if best is not None:
            self._process(*best)

    def _takes_over(self, sender: object, heard: float) -> bool:
        """Whether a face frame from a sender other than the followed one takes the stream:
        the first sender does; later, only one that has streamed CLAIM s while the followed
        one has been silent HANDOVER s, and no other live stream has streamed longer (a
        tracker that kept streaming beats senders that appear and vanish)."""
        if self._source is None:
            return True
        c = self._claims.get(sender)
        since = c[0] if c is not None and heard - c[1] < CLAIM else heard
        self._claims.put(sender, (since, heard))
        if heard - self._source_seen < HANDOVER or heard - since < CLAIM:
            return False
        return all(s >= since for s, last in self._claims.values() if heard - last < CLAIM)

    def _reset(self) -> None:
        self.cleaner.reset()
        if self.pose is not None:
            self.pose.reset()
        if self.recorder is not None:
            self.recorder.restart()

    def _process(self, frame: Frame, t: float, received: int) -> None:
        src, dst = self._columns(frame.names)
        x = np.full(len(ARKIT52), np.nan)  # (52,) canonical order
        x[dst] = frame.values[src]
        if not np.isfinite(x).any():
            self.stats.missing += 1
        if self._pending is not None:  # swap(): the new cleaner from this frame on
            with self._swap_lock:
                self.cleaner, self._pending = self._pending, None
        y = self.cleaner.step(x, t)  # (52,)
        pose = self._pose(frame.pose, x, t)
        self._last_t = t
        if np.isnan(y).all():  # nothing seen yet: nothing to send
            return
        if self.recorder is not None:
            arrival = time.time()  # s since the epoch: the time of day when none is sent
            self.recorder.add(t, x, y, frame.pose, pose, frame.timecode, arrival)
        if self._vmc_out:
            values = frame.values.copy()  # non-ARKit channels pass unchanged
            values[src] = y[dst]
            out = Frame(frame.names, values, t, pose, frame.passthrough, positions=frame.positions)
        else:
            y = np.nan_to_num(y)
            out = Frame(ARKIT52, y, t, pose, (), frame.subject, frame.device, frame.timecode)
        data = self.encoder.encode(out)
        self.stats.frames_out += 1  # counted before the peer can see it
        if self._send(data):
            self.stats.record(time.perf_counter_ns() - received)
        else:
            self.stats.frames_out -= 1

    def _pose(self, pose: np.ndarray | None, x: np.ndarray, t: float) -> np.ndarray | None:
        """The cleaned (9,) angles of a frame's pose (see the module docstring)."""
        if pose is None or self.pose is None or len(pose) != 9:
            return pose
        seen = np.isfinite(x).any()  # tracking loss: the angles hold too
        out = np.asarray(self.pose.step(pose if seen else np.full(9, np.nan), t))
        return np.where(np.isnan(pose) | np.isnan(out), pose, out)  # absent stays absent

    def _send(self, data: bytes) -> bool:
        try:
            self._out.send(data)
            return True
        except OSError:
            self.stats.send_errors += 1
            return False


def probe(cleaner: Stepper) -> None:
    """FacecleanError when ``cleaner`` turns a plain face stream (1 s at 60 fps, every
    weight moving in [0.2, 0.8]) into non-finite output: a cleaner that would erase every
    frame does not start (filters/base.py ``check_finite``). The cleaner is reset after."""
    from faceclean.filters.base import check_finite

    while getattr(cleaner, "inner", None) is not None:  # level and calibration wrappers:
        cleaner = cleaner.inner  # the cleaner itself (their steps have effects)
    t = np.arange(60) / 60.0  # s
    x = 0.5 + 0.3 * np.sin(2 * np.pi * t[:, None] + np.arange(len(ARKIT52)))  # (60, 52)
    y = np.array([cleaner.step(row, ti) for row, ti in zip(x, t, strict=True)])
    cleaner.reset()
    check_finite(x, y, getattr(cleaner, "name", None) or type(cleaner).__name__)


def _same_socket(a: tuple, b: tuple) -> bool:
    """True when a datagram sent to ``a`` reaches the socket bound to ``b``: same port, and
    the same host, or ``b`` bound to every interface."""
    if a[1] != b[1]:
        return False
    return a[0] == b[0] or b[0] in ("0.0.0.0", "::")
