"""``faceclean relay ... --ui``: the tuning page on the running relay.

The relay hands every cleaned frame to a ``Tap`` (its ``recorder`` slot: ``add``,
``restart``), which costs the relay thread a few row copies into a ring and passes the
frame on to the ``--record`` recorder and to a recording started from the page. A push
thread sends the page what is new at most ``RATE`` times a second, aggregated: the
frames of the channels the page plots, the newest input and output for the faces, the
relay's counters and latency; never a message per frame.

A change of the tuning builds the new cleaner here, outside the relay thread, as
``relay`` builds it (``Tuning.build``), warms it up and probes it as the relay does
(a cleaner that would erase the face is refused, with the CLI's reason), primes it on
the last ``PRIME`` s of input so its state is the stream's, and hands it over with
``Relay.swap``: the relay takes it between two frames, none lost.

Calibrate holds a neutral face for N s: the next N s of raw input (before any level
mapping), with a countdown on the page; the mapping is ``calibrate`` on them as
``--calibrate-seconds`` measures it (the tops of a loaded calibration kept), and the
new cleaner is swapped in as for any change. The guided calibration (ui/guided.py)
records from the same ``Tap`` (one of its recorders while the script runs), ticked by the
push thread. What the command should print (the browser's priority lowered, a guided
calibration's outcome) goes to ``say``, the CLI's callback: this module prints nothing.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from faceclean.adjust import Adjust
from faceclean.animation import Animation
from faceclean.calibration import MIN_FRAMES
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.ui.guided import Panel
from faceclean.ui.server import Client
from faceclean.ui.session import MAX_PATH, Base, number, seq, text
from faceclean.ui.tuning import Tuning

RATE = 30.0  # messages a second to a page, at most (a screen's rate)
RING = 8192  # frames kept for the page (68 s at 120 fps)
PRIME = 1.0  # s of recent input a new cleaner is stepped over before the swap
STATS_EVERY = 0.5  # s between counter updates
MAX_NEUTRAL = 60.0  # s, the longest neutral hold
MAX_CURVES = 64  # channels one page may plot
BACKLOG = 512  # frames one message carries at most (a page that fell behind skips)


class Tap:
    """The relay's ``recorder``: every cleaned frame into a ring, and on to recorders."""

    def __init__(self, recorder: Any = None) -> None:
        self.t = np.zeros(RING)  # s, sender time
        self.x = np.zeros((RING, len(ARKIT52)))  # input as received (NaN: absent)
        self.y = np.zeros((RING, len(ARKIT52)))  # cleaned output
        self.n = 0  # frames seen; row i % RING holds frame i
        self.restarts = 0
        self.recorders = [r for r in (recorder,) if r is not None]  # replaced, never changed
        self._joining = threading.Lock()  # the page's and the guided panel's joins and leaves
        self.hold: list[tuple[float, np.ndarray]] | None = None  # a neutral being measured
        self.hold_s = 0.0  # s it lasts: complete at the first frame this long after its first
        self.held = False  # complete

    def __len__(self) -> int:
        return self.n

    def join(self, recorder: Any) -> None:
        """Pass frames on to ``recorder`` too, from the next frame on (any thread)."""
        with self._joining:
            self.recorders = [*self.recorders, recorder]

    def leave(self, recorder: Any) -> None:
        with self._joining:
            self.recorders = [r for r in self.recorders if r is not recorder]

    def restart(self) -> None:
        self.restarts += 1
        for r in self.recorders:
            r.restart()

    def add(self, t: float, x: np.ndarray, y: np.ndarray, pose: np.ndarray | None, *more) -> None:
        """A cleaned frame (Recorder.add's arguments: ``more`` the cleaned pose, the
        timecode and the arrival time, passed on to the recorders)."""
        i = self.n % RING
        self.t[i], self.x[i], self.y[i] = t, x, y
        self.n += 1  # published after the row is written
        hold = self.hold
        if hold is not None and not self.held:
            hold.append((t, np.array(x)))
            # complete after hold_s, with MIN_FRAMES frames at least (a stalled sender)
            self.held = t - hold[0][0] >= self.hold_s and len(hold) >= MIN_FRAMES
        for r in self.recorders:
            r.add(t, x, y, pose, *more)

    def since(self, first: int) -> tuple[int, slice | np.ndarray]:
        """(frames now, the ring rows of frames first..now-1, at most RING)."""
        n = self.n
        first = max(first, n - RING + 1)
        return n, np.arange(first, n) % RING


class Live(Base):
    """The page on ``relay`` (bound already), its cleaner from ``tuning``."""

    mode = "live"
    MESSAGES = (*Base.MESSAGES, "channels", "calibrate", "record", "gl")

    def __init__(self, tuning: Tuning, relay: Any, tap: Tap, describe: str, nice: int = 0,
                 say: Callable[[str], None] | None = None, script: Any = None) -> None:  # fmt: skip
        super().__init__(tuning, say)
        self.guided = Panel(self, tap=tap, script=script)  # script: None, the shipped one
        self.relay, self.tap, self.what = relay, tap, describe
        self.nice = nice  # a software-drawn page's browser yields at this nice (ui/priority.py)
        self._yielded = False
        self.channels = [ARKIT52.index(c) for c in ("jawOpen", "eyeBlinkLeft")]
        self.calibrating: tuple[float, float | None] | None = None  # (seconds, t0)
        self.page_recorder: Any = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._push, name="faceclean-ui-push", daemon=True)

    def start(self) -> Live:
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop pushing; a recording the page started and never stopped is saved and said
        (Ctrl-C lost it, in silence)."""
        self._stop.set()
        self._thread.join(5.0)
        recorder, self.page_recorder = self.page_recorder, None
        if recorder is None:
            return
        self.tap.leave(recorder)
        if not len(recorder):
            line = f"the page's recording to {recorder.path}: no frame came, no file written"
        else:
            there = recorder.there()
            said = [f"{p}{' (replaced)' if p in there else ''}" for p in recorder.save()]
            line = f"the page's recording: {len(recorder)} frames to {' and '.join(said)}"
        if self.say is not None:
            self.say(line)

    def hello(self) -> dict[str, Any]:
        return {**super().hello(), "relay": self.what}

    # -- a new tuning: built, checked and primed here, swapped in between two frames -------
    def apply(self, tuning: Tuning) -> None:
        from faceclean.relay.loop import probe, warm_up

        cleaner = tuning.build(ARKIT52)
        warm_up(cleaner)
        probe(cleaner)  # one that would erase the face is refused, with the CLI's reason
        n, rows = self.tap.since(0)
        t = self.tap.t[rows]
        recent = rows[t > t[-1] - PRIME] if len(rows) else rows
        for i in recent:
            cleaner.step(self.tap.x[i], self.tap.t[i])
        self.relay.swap(cleaner)

    # -- messages -------------------------------------------------------------------------
    def on_channels(self, client: Client, m: dict[str, Any]) -> None:
        names = m.get("names")
        if not isinstance(names, list) or len(names) > MAX_CURVES:
            raise FacecleanError(f"names: expected a list of at most {MAX_CURVES} channels")
        unknown = [str(n)[:40] for n in names if n not in ARKIT52]
        if unknown:
            raise FacecleanError(f"names: {unknown[0]!r} is not an ARKit channel")
        self.channels = [ARKIT52.index(n) for n in names]

    def on_gl(self, client: Client, m: dict[str, Any]) -> None:
        """The page says how it draws; on the CPU (software GL), its browser yields to the
        relay (ui/priority.py), once a run, in a thread of its own (it reads /proc)."""
        software = m.get("software")
        if not isinstance(software, bool):
            raise FacecleanError("software: expected true or false")
        if not software or not self.nice or self._yielded or client is None:
            return
        self._yielded = True
        server = client.connection.local_address[1]
        page = client.connection.remote_address[1]

        def lower() -> None:
            from faceclean.ui import priority

            said = priority.lower_page(server, page, self.nice)
            if self.say is not None:
                self.say(said)

        threading.Thread(target=lower, name="faceclean-ui-nice", daemon=True).start()

    def on_calibrate(self, client: Client, m: dict[str, Any]) -> None:
        seconds = number(m, "seconds", 0.05, MAX_NEUTRAL, 1.0)
        with self.lock:
            self.calibrating = (seconds, None)
            self.tap.hold, self.tap.hold_s, self.tap.held = None, seconds, False
            self.tap.hold = []
        self.broadcast(
            {"type": "calibrating", "seq": seq(m), "seconds": seconds, "remaining": seconds}
        )

    def on_record(self, client: Client, m: dict[str, Any]) -> None:
        from faceclean.relay.recorder import Recorder

        action = m.get("action")
        if action == "start":
            if self.page_recorder is not None:
                raise FacecleanError("already recording: stop first")
            recorder = Recorder(text(m, "path", limit=MAX_PATH))  # the --record checks
            self.page_recorder = recorder
            self.tap.join(recorder)
            there = " and ".join(map(str, recorder.there()))  # said now, while one can stop
            self.broadcast({"type": "recording", "on": True, "path": str(recorder.path),
                            "replaces": there})  # fmt: skip
        elif action == "stop":
            recorder = self.page_recorder
            if recorder is None:
                raise FacecleanError("not recording")
            self.tap.leave(recorder)
            self.page_recorder = None
            there = " and ".join(map(str, recorder.there()))
            take, cleaned = recorder.save()
            self.broadcast(
                {
                    "type": "recording",
                    "on": False,
                    "path": f"{take} and {cleaned}",
                    "frames": len(recorder),
                    "replaces": there,
                }
            )
        else:
            raise FacecleanError("action: start or stop")

    # -- the push thread --------------------------------------------------------------------
    def _push(self) -> None:
        sent, restarts = 0, 0
        last_stats, stats_n, stats_t = 0.0, 0, time.monotonic()
        while not self._stop.wait(1.0 / RATE):
            if not self.clients:  # nobody looks: nothing piles up for a page to come
                sent = self.tap.n
            n, rows = self.tap.since(max(sent, self.tap.n - BACKLOG))
            sent = n
            self._calibration()
            self.guided.tick()
            now = time.monotonic()
            stats = None
            if now - last_stats >= STATS_EVERY:
                stats = self._stats(n - stats_n, now - stats_t)
                last_stats, stats_n, stats_t = now, n, now
            if not self.clients or (not len(rows) and stats is None):
                continue
            restart = self.tap.restarts != restarts
            restarts = self.tap.restarts
            cols = list(self.channels)
            message: dict[str, Any] = {
                "type": "frames",
                "t": [round(float(v), 5) for v in self.tap.t[rows]],
                "channels": cols,
                "x": _rows(self.tap.x[rows][:, cols]),
                "y": _rows(self.tap.y[rows][:, cols]),
                "restart": restart,
            }
            if len(rows):
                message["fx"] = _rows(self.tap.x[rows[-1:]])[0]
                message["fy"] = _rows(self.tap.y[rows[-1:]])[0]
            if stats is not None:
                message["stats"] = stats
            self.broadcast(message)

    def _stats(self, frames: int, seconds: float) -> dict[str, Any]:
        s = self.relay.stats
        p50, p99 = s.percentile_ms(50), s.percentile_ms(99)
        sender = self.relay.sender
        return {
            "sender": None if sender is None else ":".join(str(p) for p in sender[:2]),
            "rate": frames / seconds if seconds > 0 else 0.0,
            "frames_in": s.frames_in,
            "frames_out": s.frames_out,
            "dropped": s.dropped,
            "malformed": s.malformed,
            "p50": None if np.isnan(p50) else p50,
            "p99": None if np.isnan(p99) else p99,
        }

    def _calibration(self) -> None:
        """The countdown, then the measured neutral swapped in (on the push thread)."""
        from faceclean.calibration import tops_of

        with self.lock:
            if self.calibrating is None or self.tap.hold is None:
                return
            seconds, _ = self.calibrating
            held, hold = self.tap.held, list(self.tap.hold)
        if not hold:
            return
        elapsed = hold[-1][0] - hold[0][0]
        if not held:
            remaining = seconds - elapsed
            self.broadcast({"type": "calibrating", "seconds": seconds, "remaining": remaining})
            return
        with self.lock:
            self.tap.hold, self.calibrating = None, None
        anim = Animation(np.array([h[0] for h in hold]), np.array([h[1] for h in hold]), ARKIT52)
        self.broadcast({"type": "calibrating", "seconds": seconds, "remaining": 0})
        try:
            old = self.tuning.calibration
            tops = tops_of(old) if old is not None else None
            live = self.tuning.neutral(anim, elapsed + 1e-9, "live", tops or None)
            live = _with_hold(live, hold[0][0], hold[-1][0])
            self.use(self.tuning.calibrated(live).with_choice(), None, "calibrate")
        except FacecleanError as e:
            self.broadcast({"type": "error", "for": "calibrate", "message": f"faceclean: {e}"})


def _with_hold(adjust: Adjust, t0: float, t1: float) -> Adjust:
    """The calibration with the sender times (s) of its neutral hold in its facts."""
    return Adjust(adjust.rules, {**adjust.facts, "hold": [t0, t1]}, adjust.scale,
                  adjust.adaptation)  # fmt: skip


def _rows(a: np.ndarray) -> list[list[float | None]]:
    """(n, k) values as lists, NaN as None (JSON null), 5 decimals."""
    r = np.round(a, 5)
    return [[None if v != v else v for v in row] for row in r.tolist()]
