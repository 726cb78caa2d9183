"""``faceclean ui take.csv``: tune on a recorded take, scrub and play it, export.

The take is cleaned as ``faceclean clean`` cleans it (``Tuning.clean``: the levels, then
the cleaner's ``clean`` over the take's own columns); the page gets the input once and
the cleaned take after every change, both as ARKit-52 float32 arrays in binary messages.
A change is cleaned twice, in a worker thread, newest change first: the window the page
shows (from ``WARM`` s before it, the cleaner started there) at once, then the whole
take, which replaces it; a newer change skips whatever older work is left. One Euro and the
default clean their runs of usual frames in a compiled loop here (filters/compiled.py).

Binary message: uint32 little-endian header length, the JSON header
``{"kind": "input"|"cleaned", "seq", "start", "count", "channels": 52}``, zero padding to
a multiple of 4 bytes, then ``count x 52`` float32 values (NaN: missing).
Calibrate measures the neutral as ``faceclean calibrate --neutral S`` does, on the take
from the playhead on; export writes the cleaned take as ``clean -o`` would; the guided
calibration's panel (ui/guided.py) fits on the take as ``calibrate --guided take.csv`` does.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import numpy as np

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.ui.guided import Panel
from faceclean.ui.server import Client
from faceclean.ui.session import MAX_PATH, Base, number, seq, text
from faceclean.ui.tuning import Tuning

WARM = 2.0  # s cleaned before the shown window, so a causal cleaner has settled there
PROBE = 2.0  # s of the take a new tuning must clean before it is taken (``apply``)
MAX_NEUTRAL = 60.0  # s, the longest neutral hold
F32_MAX = float(np.finfo(np.float32).max)


def packet(kind: str, seq: int | None, start: int, values: np.ndarray) -> bytes:
    """One binary message (module docstring): values (n, 52); NaN is the one missing
    mark, so an infinite value, or one beyond float32, goes out as NaN, never inf."""
    values = np.asarray(values, np.float64)
    values = np.where(np.abs(values) <= F32_MAX, values, np.nan)
    head = json.dumps(
        {"kind": kind, "seq": seq, "start": start, "count": len(values), "channels": 52}
    ).encode()
    head += b" " * (-(len(head) + 4) % 4)
    return len(head).to_bytes(4, "little") + head + np.asarray(values, "<f4").tobytes()


class Offline(Base):
    """The take at ``path`` under ``tuning``."""

    mode = "offline"
    MESSAGES = (*Base.MESSAGES, "view", "calibrate", "export")

    def __init__(self, path: str, tuning: Tuning, script: Any = None) -> None:
        from faceclean import io

        self.path = Path(path)
        self.take: Animation = io.load(path)
        if not self.take.valid.any():
            raise FacecleanError(f"{self.path.name}: no valid frame to tune on")
        self.times = np.asarray(self.take.times, np.float64)  # (N,) s
        self.input, self.present = self.take.arkit()  # (N, 52)
        super().__init__(tuning)
        self.guided = Panel(self, take=lambda: (self.take, self.path.name), script=script)
        self.cleaned: np.ndarray | None = None  # (N, 52) of the whole take, current tuning
        self.cleaned_seq: int | None = None
        self.good: Tuning | None = None  # the last tuning that cleaned the whole take
        self.window = (0.0, min(10.0, float(np.nanmax(self.times))))  # s, what the page shows
        self._work = threading.Condition()
        self._job: tuple[Tuning, int | None, str | None] | None = None
        self._worker = threading.Thread(target=self._run, name="faceclean-ui-clean", daemon=True)
        self._job = (self.tuning, None, None)
        self._worker.start()

    def hello(self) -> dict[str, Any]:
        t0 = float(np.nanmin(self.times))
        return {
            **super().hello(),
            "take": self.path.name,
            "frames": int(self.take.n_frames),
            "missing": int((~self.take.valid).sum()),
            "rate": float(self.take.rate),
            "times": [round(float(t) - t0, 6) for t in self.times],
            "present": [bool(p) for p in self.present],
        }

    def attach(self, client: Client) -> None:
        super().attach(client)
        client.send_bytes(packet("input", None, 0, self.input))
        with self.lock:
            cleaned, s = self.cleaned, self.cleaned_seq
        if cleaned is not None:
            client.send_bytes(packet("cleaned", s, 0, cleaned))

    def apply(self, tuning: Tuning) -> None:
        """Refuse, with the CLI's reason, a tuning that does not clean the take's first
        PROBE s as ``clean`` would (its ``check_finite``: Kalman ``r=1e300`` turns the
        finite take into NaN): the page's state stays what it was. What only fails
        further on is refused by the worker, which puts the last good tuning back."""
        t = self.times - np.nanmin(self.times)
        n = max(int(np.searchsorted(t, PROBE, side="right")), 8)
        tuning.clean(Animation(self.times[:n], self.take.values[:n], self.take.names))

    def use(self, tuning: Tuning, seq: int | None = None, answers: str | None = None) -> None:
        super().use(tuning, seq, answers)
        with self._work:
            self._job = (tuning, seq, answers)
            self._work.notify()

    # -- messages -------------------------------------------------------------------------
    def on_view(self, client: Client, m: dict[str, Any]) -> None:
        t0 = number(m, "t0", -1e9, 1e9)
        t1 = number(m, "t1", t0, 1e9)
        self.window = (t0, t1)

    def on_calibrate(self, client: Client, m: dict[str, Any]) -> None:
        seconds = number(m, "seconds", 0.05, MAX_NEUTRAL, 1.0)
        start = number(m, "start", 0.0, 1e9, 0.0)
        t = self.times - np.nanmin(self.times)
        keep = np.flatnonzero(~(t < start))  # from the playhead on (NaN times kept)
        part = Animation(self.times[keep], self.take.values[keep], self.take.names)
        adjust = self.tuning.neutral(part, seconds, self.path.name)
        self.use(self.tuning.calibrated(adjust).with_choice(), seq(m), "calibrate")

    def on_export(self, client: Client, m: dict[str, Any]) -> None:
        from faceclean import io

        path = text(m, "path", limit=MAX_PATH)
        with self.lock:
            tuning = self.tuning
        replaced = io.paths.verb(path) == "replaced"  # said on the page, never in silence
        io.save(tuning.clean(self.take), path)
        client.send({"type": "exported", "seq": seq(m), "path": path, "replaced": replaced})

    # -- the worker -----------------------------------------------------------------------
    def _run(self) -> None:
        from faceclean.filters import compiled

        compiled.enable()  # this process cleans the take on every change (filters/compiled.py)
        while True:
            with self._work:
                while self._job is None:
                    self._work.wait()
                tuning, s, answers = self._job
                self._job = None
            try:
                self._window(tuning, s)
                if self._newer():
                    continue
                full = tuning.clean(self.take).arkit()[0]
            except FacecleanError as e:  # e.g. a model that erases the face further on
                self._refused(tuning, s, answers, e)
                continue
            with self.lock:
                self.cleaned, self.cleaned_seq, self.good = full, s, tuning
            self.broadcast_bytes(packet("cleaned", s, 0, full))

    def _refused(
        self, tuning: Tuning, s: int | None, answers: str | None, e: FacecleanError
    ) -> None:
        """The take refused ``tuning``: the pages are told which request failed, and the
        last tuning that cleaned the whole take is the state again (so a save never
        writes what was refused)."""
        self.broadcast({"type": "error", "for": answers, "seq": s, "message": f"faceclean: {e}"})
        with self.lock:
            back = self.good if self.tuning is tuning and self.good is not None else None
            if back is not None:
                self.tuning = back
        if back is not None:
            self.broadcast({"type": "state", "seq": s, **back.describe()})
            with self.lock:
                cleaned, at = self.cleaned, self.cleaned_seq
            if cleaned is not None:
                self.broadcast_bytes(packet("cleaned", at, 0, cleaned))

    def _newer(self) -> bool:
        with self._work:
            return self._job is not None

    def _window(self, tuning: Tuning, s: int | None) -> None:
        """Clean the shown window (from WARM s before it) and send it, when it is a part."""
        t = self.times - np.nanmin(self.times)
        t0, t1 = self.window
        inside = np.flatnonzero((t >= t0 - WARM) & (t <= t1))
        if len(inside) == 0 or len(inside) > 0.8 * len(t):
            return
        a, b = int(inside[0]), int(inside[-1]) + 1
        part = Animation(self.times[a:b], self.take.values[a:b], self.take.names)
        self.broadcast_bytes(packet("cleaned", s, a, tuning.clean(part).arkit()[0]))
