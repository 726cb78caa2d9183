"""Calibration: a per-channel level mapping (faceclean.adjust) measured from a short take.

The take is a neutral hold (its first ``neutral_s`` seconds; the whole take when it is
shorter) and, optionally, a range-of-motion pass after it. Per ARKit channel present:

    neutral = median over the neutral hold                     (blinks in it do not move it)
    noise   = 1.4826 * MAD over the neutral hold               (robust standard deviation)
    top     = HIGH-th percentile over the whole take           (robust: not the maximum)
    moved   = top - neutral > max(MOVE_MIN, NOISE_K * noise)

    lifted:   offset = neutral, gain = 1 / (top - neutral)  (top maps to 1; at most MAX_GAIN)
    else:     offset = neutral, gain = 1 / (1 - neutral)    (1 still maps to 1)
    neutral >= 0.5 and unmoved: the identity (a resting level that high is not trusted)
    always:   curve 1, clamp [0, 1]

A moved channel is lifted only with evidence that its top is the channel's full range
(issue 19: an iPhone take's real 0.08 jawLeft peak was lifted to 1.0, gain 17):
- ``rom=True``: the take after the neutral hold is a range-of-motion pass, every
  expression as far as it goes (``calibrate --rom``): every moved channel is lifted;
- a tracker profile (``channels.TRACKERS``, ``calibrate --tracker mediapipe``) names the
  channels that tracker under-reads (MediaPipe's eyeWide, cheekSquint, noseSneer): those
  are lifted. The default profile, ``arkit``, names none.
Otherwise the neutral is subtracted and the range kept: a small real movement stays small.
The gain is capped at MAX_GAIN (noise is lifted with the signal); ``faceclean calibrate``
prints every channel whose gain exceeds REPORT_GAIN.

Eyelids (eyeBlinkLeft/Right) are blink-aware: their neutral is open (the median of the
hold, which brief blinks do not move), and their top is not a percentile of all frames
but the BLINK_Q quantile of the peaks of the blinks the take holds (a blink is a rise of
at least BLINK_RISE above neutral), so the blinks seen reach full closure; with no blink
seen the top stays 1, so a full closure still reads 1 after the neutral is subtracted.
Neither case lets the neutral subtraction stop a blink. Curve stays 1 (linear): one
take's value distribution says how far a channel goes, not how it should ease.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from faceclean.adjust import Adjust, apply_levels
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, DEFAULT_TRACKER, TRACKERS
from faceclean.errors import FacecleanError
from faceclean.filters.base import Stepper

NEUTRAL_S = 1.0  # s, default neutral hold at the start of the take
HIGH = 99.5  # percentile taken as a channel's top
MOVE_MIN = 0.01  # a channel whose top is within this of neutral did not move
NOISE_K = 6.0  # ... nor one within this many noise standard deviations
MAX_GAIN = 10.0  # lifts a channel that peaks at 0.1 over neutral to 1, not more
REPORT_GAIN = 2.0  # the calibrate command names every channel with a gain above this
BLINKS = ("eyeBlinkLeft", "eyeBlinkRight")
BLINK_RISE = 0.25  # a blink rises at least this far above the open eye
BLINK_Q = 25.0  # percentile of the blink peaks taken as full closure
MIN_FRAMES = 5  # a neutral hold needs this many valid frames


MAX_NEUTRAL_S = 3600.0  # s: a longer "hold" (inf, 1e400) is a typing slip, not a neutral


def calibrate(
    anim: Animation,
    neutral_s: float = NEUTRAL_S,
    *,
    tops: Mapping[str, float] | None = None,
    take: str | None = None,
    rom: bool = False,
    tracker: str = DEFAULT_TRACKER,
) -> Adjust:
    """The mapping of the module docstring for ``anim``'s ARKit channels.

    ``tops`` (canonical name -> top) replaces the tops measured here: a live neutral
    re-measured on top of an earlier full calibration keeps that calibration's range
    (that calibration's evidence: those channels are lifted to the tops given).
    ``rom``: the take holds a range of motion; ``tracker``: a ``channels.TRACKERS`` name.
    """
    if not 0 < neutral_s <= MAX_NEUTRAL_S:
        raise FacecleanError(
            f"calibration: the neutral hold must be > 0 and at most {MAX_NEUTRAL_S:g} s "
            f"(got {neutral_s:g})"
        )
    if tracker not in TRACKERS:
        raise FacecleanError(
            f"calibration: unknown tracker {tracker!r} (known: {', '.join(TRACKERS)})"
        )
    weak = set(TRACKERS[tracker])
    values, present = anim.arkit()  # (N, 52), NaN rows for missing frames
    valid = anim.valid
    if not present.any():
        raise FacecleanError("calibration: the take has no ARKit blendshape channels")
    if not valid.any():
        raise FacecleanError("calibration: every frame of the take is a tracking loss")
    present &= np.isfinite(values).any(axis=0)  # a column without one value is absent
    if valid.sum() < MIN_FRAMES:
        raise FacecleanError(f"calibration: the take has fewer than {MIN_FRAMES} valid frames")
    t, x = anim.times[valid], values[valid]
    if np.any(~(np.diff(t) > 0)):  # the neutral hold is "the first N s": times must run on
        raise FacecleanError("calibration: the take's times do not increase")
    hold = x[t <= t[0] + neutral_s]
    if len(hold) < MIN_FRAMES:
        raise FacecleanError(
            f"calibration: fewer than {MIN_FRAMES} frames in the first {neutral_s:g} s"
        )
    if rom and len(hold) == len(x):  # its tops would be the hold's: nothing was moved
        raise FacecleanError(
            f"calibration: the take ends within its neutral hold ({neutral_s:g} s): a range "
            "of motion (--rom) follows the hold (a shorter --neutral, or the whole take)"
        )
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: absent channels
        neutral = np.nanmedian(hold, axis=0)  # (52,)
        noise = 1.4826 * np.nanmedian(np.abs(hold - neutral), axis=0)
        top = np.nanpercentile(x, HIGH, axis=0)
    rules, chans, moved, lifted, closed = [], {}, [], [], []
    for i, name in enumerate(ARKIT52):
        if not present[i] or not np.isfinite(neutral[i]):
            continue
        n = float(neutral[i])
        hi = _blink_top(x[:, i], n) if name in BLINKS else float(top[i])  # None: no blink
        given = tops is not None and name in tops
        if given:
            hi = float(tops[name])  # type: ignore[index]
        offset = n
        moves = hi is not None and hi - n > max(MOVE_MIN, NOISE_K * float(noise[i]))
        if moves:
            moved.append(name)
        # evidence that the top is the full range: blinks seen, a range of motion, the
        # tracker's profile, or an earlier calibration's top
        if moves and (name in BLINKS or rom or name in weak or given):
            gain = min(1.0 / (hi - n), MAX_GAIN)  # the observed range onto [0, 1]
            if hi - n < 1.0 - n - 1e-9:
                (closed if name in BLINKS else lifted).append(name)
        elif n < 0.5:
            gain, hi = 1.0 / (1.0 - n), 1.0  # unmoved: [neutral, 1] onto [0, 1]
        else:
            offset, gain, hi = 0.0, 1.0, 1.0  # a "neutral" this high is no neutral: identity
        rules += [(name, "offset", offset), (name, "gain", gain)]
        rules += [(name, "curve", 1.0), (name, "clamp", (0.0, 1.0))]
        chans[name] = {
            "neutral": _r(n), "noise": _r(float(noise[i])), "top": _r(hi), "gain": _r(gain)
        }  # fmt: skip
    facts = {
        "take": take,
        "frames": int(valid.sum()),
        "neutral_s": float(min(neutral_s, t[-1] - t[0])),
        "tracker": tracker,
        "rom": bool(rom),
        "moved": moved,
        "lifted": lifted,
        "closed": closed,  # eyelids scaled so the blinks seen close fully
        "channels": chans,
    }
    return Adjust(tuple(rules), facts)


def high_gains(adjust: Adjust, above: float = REPORT_GAIN) -> list[tuple[str, float, float]]:
    """(channel, gain, top) of every calibrated channel whose gain exceeds ``above``."""
    lv = adjust.levels(ARKIT52)
    chans = adjust.facts.get("channels", {})
    out = []
    for i, name in enumerate(ARKIT52):
        if lv.gain[i] > above:
            top = chans.get(name, {}).get("top") if isinstance(chans.get(name), dict) else None
            out.append((name, float(lv.gain[i]), float("nan") if top is None else float(top)))
    return out


def tops_of(adjust: Adjust) -> dict[str, float]:
    """The measured tops a calibration file carries (for a live neutral on top of it)."""
    chans = adjust.facts.get("channels", {})
    return {n: float(c["top"]) for n, c in chans.items() if isinstance(c, dict) and "top" in c}


def _blink_top(x: np.ndarray, neutral: float) -> float | None:
    """Full closure for one eyelid (N,): the BLINK_Q quantile of blink peaks; None if no
    blink (the caller then keeps 1 as full closure)."""
    up = np.nan_to_num(x, nan=neutral) > neutral + BLINK_RISE  # (N,) inside a blink
    edges = np.flatnonzero(np.diff(np.r_[False, up, False].astype(np.int8)))
    peaks = [float(np.nanmax(x[a:b])) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return float(np.percentile(peaks, BLINK_Q)) if peaks else None


def _r(v: float) -> float:
    return round(v, 6)


class LiveCalibration(Stepper):
    """A stream cleaner that calibrates its neutral from the first ``seconds`` of a stream.

    Until then frames pass through ``base`` (a calibration file's mapping, or none) and
    the cleaner as usual; from the first frame at least ``seconds`` after the stream's
    first one (and MIN_FRAMES frames with a face), the mapping is ``base`` with the
    neutral measured over those seconds (the tops of ``base``'s calibration kept when it
    has them, else blink-aware defaults: ``calibrate`` above), then ``overrides`` on top.
    ``reset()`` (a new stream) forgets the measured neutral: each stream calibrates on
    its own first seconds. A cleaner that reads the face's rest itself (the MediaPipe map,
    ``set_rest_reading``) gets no levels: it was fitted on raw scores and already measures
    this stream's rises from its own rest (levels before it cost on 7 of 10 held-out
    faces: docs/CALIBRATION.md); the facts then say ``"levels": "none"``.
    ``on_done(adjust)`` is called once per stream when the mapping is measured.
    """

    def __init__(
        self,
        inner: Any,
        seconds: float,
        base: Adjust | None = None,
        overrides: Adjust | None = None,
        names: tuple[str, ...] = ARKIT52,
        on_done: Callable[[Adjust], None] | None = None,
    ) -> None:
        if not seconds > 0:
            raise FacecleanError(f"--calibrate-seconds must be > 0 (got {seconds})")
        self.inner, self.seconds, self.names, self.on_done = inner, float(seconds), names, on_done
        self.name = getattr(inner, "name", "cleaner")
        self.reads_rest = getattr(inner, "set_rest_reading", None) is not None
        self.base, self.overrides = base or Adjust(), overrides or Adjust()
        self._before = self.base.merged(self.overrides).levels(names)
        self._tops = tops_of(self.base)
        from faceclean.adaptation import after

        self._after = after(inner, self.base.adaptation, names)  # a guided calibration's
        self.reset()

    def reset(self) -> None:
        self.inner.reset()
        self.adjust: Adjust | None = None  # the measured mapping, once done
        self._levels = self._before
        self._t: list[float] = []
        self._x: list[np.ndarray] = []

    def warm_up(self) -> None:
        """Warm the inner cleaner (relay.loop.warm_up) without measuring a neutral."""
        from faceclean.relay.loop import warm_up

        warm_up(self.inner)

    def step(self, frame: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        x = np.asarray(frame, dtype=np.float64)
        if self.adjust is None and np.isfinite(t):
            self._collect(x, float(t))
        y = self.inner.step(apply_levels(self._levels, x), t)
        return y if self._after is None else self._after(y)

    def _collect(self, x: np.ndarray, t: float) -> None:
        self._t.append(t)
        self._x.append(x.copy())
        elapsed = t - self._t[0]
        if elapsed < self.seconds:
            return
        anim = Animation(np.asarray(self._t), np.asarray(self._x), self.names)
        if anim.valid.sum() < MIN_FRAMES:  # too few faces yet: keep measuring, a while
            if elapsed > 10 * self.seconds:
                self._t, self._x = [], []
            return
        live = calibrate(anim, elapsed + 1e-9, tops=self._tops or None, take="live")
        if self.reads_rest:
            live = Adjust((), {**live.facts, "levels": "none"})
        self.adjust = self.base.merged(live).merged(self.overrides)
        self._levels = self.adjust.levels(self.names)
        self._t, self._x = [], []
        if self.on_done is not None:
            self.on_done(self.adjust)
