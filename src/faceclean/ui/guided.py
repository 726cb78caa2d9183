"""The page's guided calibration: the script prompted, performed, fitted and applied.

The fit is ``calibrate --guided``'s (``faceclean.guided.fit.guided``: the shipped script,
its alignment, the per-face adaptation for the page's ``--tracker``); only where the take
comes from differs. Live (``relay --ui``, ``track --camera --ui``): Start counts down
``COUNTDOWN`` s, then records the input of every frame the loop cleans (as received,
before any level mapping; each at its own time) for the script's length plus ``TAIL`` s,
while the page shows each prompt as its time comes (the clock is this process's, sent as
``elapsed``; the page draws the prompts from the script in ``hello``). Offline (``faceclean
ui take.csv``): the take is the performance. The fit runs in a thread of its own (the
loop and the push thread go on). Its result goes to the page per prompt (where it was
found, seen or why not, its channels' peak before and after against the aim) and per
channel (what the calibration changes), and is applied as any calibration is
(``Base.use``: live, between two frames), unless the take falls short of the script
(``Alignment.shortfall``): then only when asked, the rule of ``--partial``. Undo puts the
calibration in place before back; Save writes the file ``calibrate --guided -o`` writes.

From the page: ``{"type": "guided", "action": "start" | "stop" | "apply" | "undo" |
"save", "path"}``. To it: ``{"type": "guided", "phase": "countdown" (remaining s) |
"recording" (elapsed s, frames) | "fitting" | "done" (the result) | "stopped" (why)}``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from faceclean.adjust import Adjust
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, DEFAULT_TRACKER
from faceclean.errors import FacecleanError
from faceclean.guided.script import COUNTDOWN, TAIL, Script, load
from faceclean.io import atomic
from faceclean.io.paths import verb
from faceclean.ui.session import MAX_PATH, text
from faceclean.ui.tuning import json_path

PROGRESS_EVERY = 0.1  # s between progress messages while counting down or recording
ACTIONS = ("start", "stop", "apply", "undo", "save")
BUSY = ("countdown", "recording", "fitting")


class Panel:
    """The guided calibration of one page session (``session``: ui/live.py's ``Live`` or
    ui/offline.py's ``Offline``). Live, ``tap`` is the loop's ``Tap`` (this panel joins
    its recorders while it records); offline, ``take()`` gives (the take, its name)."""

    def __init__(self, session: Any, *, tap: Any = None,
                 take: Callable[[], tuple[Animation, str]] | None = None,
                 script: Script | None = None, clock: Callable[[], float] = time.monotonic,
                 ) -> None:  # fmt: skip
        self.session, self.tap, self.take = session, tap, take
        self.script = script or load()
        self.clock = clock
        self.phase = "idle"
        self.since = 0.0  # clock s the phase began
        self.rows: list[tuple[float, np.ndarray]] = []  # (frame time s, (52,) input)
        self.restarted = False  # the sender restarted while recording
        self.result: Any = None  # the last fit (faceclean.guided.fit.Guided)
        self.label = ""
        self.before: tuple[Adjust | None, str | None] | None = None  # what undo puts back
        self._shown = -1.0  # clock s of the last progress message
        self._lock = threading.Lock()

    def hello(self) -> dict[str, Any]:
        """The script, for the page to show each prompt as its time comes."""
        s = self.script
        prompts = [
            {"id": p.id, "start": p.start, "duration": p.duration, "text": p.text,
             "channels": list(p.channels)}
            for p in s.prompts
        ]  # fmt: skip
        return {"title": s.title, "seconds": s.seconds, "countdown": COUNTDOWN, "tail": TAIL,
                "live": self.take is None, "prompts": prompts}  # fmt: skip

    # -- the loop's recorder slot (live): Tap.add's arguments ------------------------------
    def add(self, t: float, x: np.ndarray, *more: Any) -> None:
        if self.phase == "recording" and (not self.rows or t > self.rows[-1][0]):
            self.rows.append((float(t), np.array(x, np.float64)))

    def restart(self) -> None:
        """A new stream (the relay says so at its first frame too): one that starts after
        frames were recorded breaks the take's times."""
        self.restarted = self.restarted or (self.phase == "recording" and bool(self.rows))

    # -- messages --------------------------------------------------------------------------
    def handle(self, client: Any, m: dict[str, Any], seq: int | None) -> None:
        action = m.get("action")
        if action not in ACTIONS:
            raise FacecleanError(f"action: one of {', '.join(ACTIONS)}")
        if action == "save":
            return self._save(client, m, seq)
        getattr(self, "_" + action)(seq)

    def _start(self, seq: int | None) -> None:
        with self._lock:
            if self.phase in BUSY:
                then = "wait for its result" if self.phase == "fitting" else "stop it first"
                raise FacecleanError(f"a guided calibration is {self.phase}: {then}")
            self.phase, self.since, self.rows, self.restarted = "countdown", self.clock(), [], False
            if self.take is not None:
                self.phase = "fitting"
        if self.take is not None:
            anim, label = self.take()  # the take the page was opened on
            self._broadcast({"phase": "fitting"})
            self._fit_in_thread(anim, label)
            return
        self.tap.join(self)
        self._broadcast({"phase": "countdown", "remaining": float(COUNTDOWN)})

    def _stop(self, seq: int | None) -> None:
        with self._lock:
            if self.phase not in ("countdown", "recording"):
                raise FacecleanError("no guided calibration is recording")
            self._end("idle")
        self._broadcast({"phase": "stopped", "why": "stopped from the page"})

    def _apply(self, seq: int | None) -> None:
        if self.result is None:
            raise FacecleanError("no guided calibration fitted yet: start one")
        self._use(seq)
        self._broadcast(self.view())

    def _undo(self, seq: int | None) -> None:
        if self.before is None:
            raise FacecleanError("no guided calibration applied: nothing to undo")
        calibration, path = self.before
        s = self.session
        s.use(s.tuning.calibrated(calibration, path).with_choice(), seq, "guided")
        self.before = None
        self._broadcast(self.view())

    def _save(self, client: Any, m: dict[str, Any], seq: int | None) -> None:
        if self.result is None:
            raise FacecleanError("no guided calibration fitted yet: start one")
        path = text(m, "path", limit=MAX_PATH)
        json_path(path, "calibration")
        atomic.check_writable(path)
        replaced = verb(path) == "replaced"  # said on the page
        self.result.adjust.save(path)  # what calibrate --guided -o writes
        s = self.session
        with s.lock:
            if s.tuning.calibration is self.result.adjust:  # applied: the command names it
                s.tuning = s.tuning.calibrated(self.result.adjust, path)
            tuning = s.tuning
        s.broadcast({"type": "state", "seq": seq, **tuning.describe()})  # before the note
        client.send({"type": "saved", "seq": seq, "what": "guided calibration", "path": path,
                     "rest": [], "replaced": replaced})  # fmt: skip

    # -- live: the countdown and the recording, ticked by the push thread --------------------
    def tick(self) -> None:
        now = self.clock()
        with self._lock:
            phase, since = self.phase, self.since
            if phase == "countdown" and now - since >= COUNTDOWN:
                self.phase, self.since = phase, since = "recording", now
            done = phase == "recording" and now - since >= self.script.seconds + TAIL
            if done:
                rows, restarted = self.rows, self.restarted
                self._end("fitting")
        if phase not in ("countdown", "recording"):
            return
        if done:
            self._recorded(rows, restarted)
        elif now - self._shown >= PROGRESS_EVERY:
            self._shown = now
            if phase == "countdown":
                self._broadcast({"phase": phase, "remaining": COUNTDOWN - (now - since)})
            else:
                self._broadcast({"phase": phase, "elapsed": now - since, "frames": len(self.rows)})

    def _end(self, phase: str) -> None:
        """Leave the loop's recorders (under the lock)."""
        if self.tap is not None:
            self.tap.leave(self)
        self.phase = phase

    def _recorded(self, rows: list[tuple[float, np.ndarray]], restarted: bool) -> None:
        why = None
        if restarted:
            why = "the stream restarted during the script (a new sender): start again"
        elif len(rows) < 2:
            why = "no face frames arrived during the script (is the tracker sending?)"
        if why is not None:
            self.phase = "idle"
            self._broadcast({"phase": "stopped", "why": why})
            return self._error(why)
        times = np.array([r[0] for r in rows])
        anim = Animation(times - times[0], np.array([r[1] for r in rows]), ARKIT52,
                         {"format": "live"})  # fmt: skip
        self._broadcast({"phase": "fitting"})
        self._fit_in_thread(anim, "live take")

    # -- the fit ------------------------------------------------------------------------------
    def _fit_in_thread(self, anim: Animation, label: str) -> None:
        threading.Thread(target=self._fit, args=(anim, label), name="faceclean-ui-guided",
                         daemon=True).start()  # fmt: skip

    def _fit(self, anim: Animation, label: str) -> None:
        from faceclean.guided.fit import guided

        tracker = self.session.tuning.tracker or DEFAULT_TRACKER
        try:
            with np.errstate(all="ignore"):
                result = guided(anim, tracker, self.script, take=label)
        except FacecleanError as e:
            self.phase = "idle"
            self._broadcast({"phase": "stopped", "why": str(e)})
            return self._error(str(e))
        except Exception as e:  # never a dead panel: one line, as cli.main says it
            self.phase = "idle"
            return self._error(f"internal error: {type(e).__name__}: {e}")
        self.result, self.label = result, label
        self.phase = "done"
        if result.alignment.shortfall() is None:
            try:
                self._use(None)
            except FacecleanError as e:
                self._error(str(e))
        self._broadcast(self.view())
        say = getattr(self.session, "say", None)
        if say is not None:
            a = result.alignment
            what = "applied" if self.applied else "not applied: " + str(a.shortfall())
            say(f"guided calibration ({label}, {anim.n_frames} frames): {a.seen} of "
                f"{len(a.segments)} prompts seen; {what}")  # fmt: skip

    def _use(self, seq: int | None) -> None:
        """Make the fitted calibration the session's (FacecleanError: refused, unchanged)."""
        s = self.session
        with s.lock:
            tuning = s.tuning
        before = (tuning.calibration, tuning.calibration_file)
        s.use(tuning.calibrated(self.result.adjust).with_choice(), seq, "guided")
        if self.before is None:
            self.before = before

    @property
    def applied(self) -> bool:
        """Whether the last fit is the session's calibration now (a later Calibrate, load
        or clear replaces it)."""
        return self.result is not None and self.session.tuning.calibration is self.result.adjust

    def view(self) -> dict[str, Any]:
        """The result for the page: per prompt, per channel, whether it is applied."""
        r = self.result
        a = r.alignment
        prompts = []
        for g in a.segments:
            pid = g.prompt.id
            prompts.append({
                "id": pid, "text": g.prompt.text, "t0": g.t0, "t1": g.t1, "seen": g.seen,
                "why": g.why, "before": r.before.get(pid), "after": r.after.get(pid),
                "aim": r.target.get(pid),
            })  # fmt: skip
        problem = a.shortfall()
        if problem is not None:  # what *apply anyway* applies, as --partial says it
            problem += f"; apply anyway fits {a.fitted_from}"
        return {
            "phase": "done", "take": self.label, "tracker": r.tracker,
            "frames": int(r.adjust.facts.get("frames", 0)), "seen": a.seen,
            "prompts": prompts, "channels": changes(r.adjust), "problem": problem,
            "applied": self.applied, "undo": self.before is not None,
        }  # fmt: skip

    def _broadcast(self, message: dict[str, Any]) -> None:
        self.session.broadcast({"type": "guided", **message})

    def _error(self, why: str) -> None:
        self.session.broadcast({"type": "error", "for": "guided", "message": f"faceclean: {why}"})


def changes(adjust: Adjust) -> list[dict[str, Any]]:
    """What a guided calibration changes, per channel, largest first: after the cleaner,
    the adaptation's gain on the channel's own excursion (1 + D_kk), its offset and the
    other channels it mixes in, whether the map reads it as its own rise alone (``own``)
    and the face's own closure (``shut``: knee, top); before it (ARKit), the levels'
    neutral and gain."""
    rows = []
    ad = adjust.adaptation
    if ad is not None:
        named = set(ad.matrix) | set(ad.offset) | set(ad.own) | set(ad.closure)
        for name in sorted(named, key=ARKIT52.index):
            row = ad.matrix.get(name, {})
            cross = sorted(((i, v) for i, v in row.items() if i != name), key=lambda c: -abs(c[1]))
            gain, offset = 1.0 + row.get(name, 0.0), ad.offset.get(name, 0.0)
            size = abs(gain - 1.0) + abs(offset) + sum(abs(v) for _, v in cross)
            entry = {"name": name, "gain": gain, "offset": offset,
                     "cross": [[i, v] for i, v in cross]}  # fmt: skip
            if name in ad.own:  # its map row replaced: listed with the largest
                entry["own"], size = True, size + 1.0
            if name in ad.closure:  # lifted so that its top reads 1
                entry["shut"] = list(ad.closure[name])
                size += 1.0 - ad.closure[name][1]
            rows.append({**entry, "size": size})
    else:
        lifted = set(adjust.facts.get("lifted", []))
        for name, c in adjust.facts.get("channels", {}).items():
            size = abs(c["gain"] - 1.0) + abs(c["neutral"])
            rows.append({"name": name, "gain": c["gain"], "neutral": c["neutral"],
                         "lifted": name in lifted, "size": size})  # fmt: skip
    return sorted(rows, key=lambda r: -r["size"])
