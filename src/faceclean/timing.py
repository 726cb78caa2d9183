"""Stream timing: tracker timestamps, resampling at new instants, runs of frame events.

Helpers of the simulator and the dataset pipeline, all vectorised over frames and channels.
"""

from __future__ import annotations

import numpy as np


def stream_times(
    t0: float, t1: float, fps: float, irregularity: float, rng: np.random.Generator
) -> np.ndarray:
    """(N,) increasing timestamps in [t0, t1] s of a tracker running at ``fps`` Hz.

    Each interval is ``(1 + irregularity * e) / fps`` with e standard normal, clipped to
    at least a fifth of the nominal period (a camera never delivers two frames at once).
    ``irregularity`` 0 gives a regular grid; webcams reach 0.2-0.4.
    """
    period = 1.0 / fps
    n = max(int(np.ceil((t1 - t0) * fps * 1.2)) + 2, 2)
    dt = period * np.maximum(1.0 + irregularity * rng.standard_normal(n), 0.2)
    t = t0 + np.concatenate([[0.0], np.cumsum(dt)])
    return t[t <= t1]


def resample(
    times: np.ndarray, values: np.ndarray, new_times: np.ndarray, max_gap: float | None = None
) -> np.ndarray:
    """Linear interpolation of (N, M) ``values`` at ``new_times`` (K,) -> (K, M).

    A result between two source frames one of which is missing (all-NaN row), or across a
    source pause longer than ``max_gap`` s (default 3 median frame periods), is NaN:
    interpolation never invents what the source did not see. Outside the source's time
    span the nearest frame is held.
    """
    times = np.asarray(times, np.float64)
    values = np.asarray(values, np.float64)
    if len(times) == 1:
        return np.repeat(values, len(new_times), axis=0)
    dts = np.diff(times)
    if max_gap is None:
        positive = dts[dts > 0]
        max_gap = 3.0 * float(np.median(positive)) if len(positive) else np.inf
    i = np.clip(np.searchsorted(times, new_times, side="right") - 1, 0, len(times) - 2)
    span = dts[i]
    w = np.clip((new_times - times[i]) / np.where(span > 0, span, 1.0), 0.0, 1.0)[:, None]
    a, b = values[i], values[i + 1]
    out = a + w * (b - a)
    at_a, at_b = w[:, 0] == 0.0, w[:, 0] == 1.0  # exact at source frames, even beside a NaN
    out[at_a], out[at_b] = a[at_a], b[at_b]
    between = (w[:, 0] > 0.0) & (w[:, 0] < 1.0)
    gap = between & ((span > max_gap) | np.isnan(a).all(1) | np.isnan(b).all(1))
    out[gap] = np.nan
    return out


def runs(n: int, rate: float, mean_len: float, rng: np.random.Generator) -> np.ndarray:
    """(n,) bool mask of random runs: starts with probability ``rate`` per frame, lengths
    geometric with mean ``mean_len`` frames (>= 1). Used for frozen, dropped and lost frames.
    """
    if n == 0 or rate <= 0.0:
        return np.zeros(n, bool)
    starts = np.flatnonzero(rng.random(n) < min(rate, 1.0))
    lengths = rng.geometric(1.0 / max(mean_len, 1.0), size=len(starts))
    edges = np.zeros(n + 1, np.int64)
    np.add.at(edges, starts, 1)
    np.add.at(edges, np.minimum(starts + lengths, n), -1)
    return np.cumsum(edges[:n]) > 0


def hold_last(values: np.ndarray, hold: np.ndarray) -> np.ndarray:
    """(N, M) values where every row marked in ``hold`` (N,) repeats the last unmarked row
    (the first rows repeat themselves when they are marked)."""
    idx = np.where(hold, 0, np.arange(len(hold)))
    return values[np.maximum.accumulate(idx)] if len(hold) else values


# Hz, the rates cameras, trackers and editors name (NTSC's are n x 1000 / 1001)
NOMINAL_RATES = (23.976, 24.0, 25.0, 29.97, 30.0, 48.0, 50.0, 59.94, 60.0, 90.0, 100.0, 119.88,
                 120.0, 240.0)  # fmt: skip
NOMINAL_TOLERANCE = 0.0025  # relative: a measured rate this close takes the named one


def nominal_rate(rate: float) -> float:
    """The named rate (NOMINAL_RATES) within 0.25 % of a measured ``rate`` Hz, else the rate
    to 1e-3. Why: a take's median frame interval comes from quantised timestamps (Live
    Link's sub-frames read 59.88 or 59.90 for a 59.94 Hz take)."""
    near = min(NOMINAL_RATES, key=lambda r: abs(r - rate))
    return near if abs(near - rate) <= NOMINAL_TOLERANCE * near else round(rate, 3)


STALE_RUN = 30  # frames in a row older than the newest before them: the times restarted


class Restarts:
    """Watches a take's times, block after block, for a restart: STALE_RUN valid frames in a
    row each at or before the newest time before them. A cleaner holds a frame older than
    its last (filters/base.py: it repeats its last output), so a take whose times restart
    (a recording restarted, takes joined, a timecode past midnight) would come out still
    from there: refused, where one late frame (a tracker's jitter) is not."""

    def __init__(self, label: str) -> None:
        self.label, self.newest, self.run, self.since = label, -np.inf, 0, 0.0

    def see(self, times: np.ndarray) -> None:
        """The next block's times (the valid frames', s); FacecleanError at a restart."""
        from faceclean.errors import FacecleanError

        t = np.asarray(times, dtype=np.float64)
        t = t[np.isfinite(t)]
        if not len(t):
            return
        before = np.maximum.accumulate(np.concatenate([[self.newest], t]))[:-1]  # (N,)
        stale = t <= before
        k = np.arange(len(t))
        fresh = np.maximum.accumulate(np.where(stale, -1, k))  # the last fresh frame so far
        run = np.where(stale, k - fresh + np.where(fresh < 0, self.run, 0), 0)  # (N,) frames
        start = np.where(fresh < 0, self.since, t[np.clip(fresh + 1, 0, len(t) - 1)])
        over = np.flatnonzero(run >= STALE_RUN)
        if len(over):
            i = int(over[0])
            back, last = _s(start[i]), _s(before[i])
            went = (f"stand still at {last} s" if start[i] == before[i] else
                    f"go back to {back} s after {last} s and stay behind")  # fmt: skip
            raise FacecleanError(
                f"{self.label}: the times {went} ({STALE_RUN} frames on): the take restarts "
                "there (a recording restarted, takes joined?), and a cleaner holds such frames "
                "still; split the take there, or give it increasing times"
            )
        self.run, self.since = int(run[-1]), float(start[-1])
        self.newest = max(self.newest, float(t.max()))


def refuse_restarts(anim, label: str) -> None:
    """A whole take (an ``Animation``) watched as ``Restarts`` watches a stream: one whose
    times restart or stand still is refused, as ``clean`` refuses it."""
    Restarts(label).see(anim.times[anim.valid])


def _s(t: float) -> str:
    """A time in s as a message shows it: ms where that reads, else 4 digits (1e308 s)."""
    return f"{t:.3f}" if abs(t) < 1e7 else f"{t:.4g}"
