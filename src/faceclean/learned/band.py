"""The tracker map's output band, widened by the stream's own noise.

A map that sums 51 inputs' rises gathers their noise, and how much noise MediaPipe gives
depends on the face: on the appearance families' pairs raw MediaPipe jitters 4.6x the
truth on painted faces and 16x on photo-textured ones (docs/RESULTS.md). A fixed deadband
(learned/tracker_map.py) wide enough for a noisy face lags a clean one. Here the band
follows the stream. Per output j, frame n, m the map's value, y the output, h the frame's
dt (s):

    v_n   = min(|d_n|, |d_{n-1}|) where d_n d_{n-1} < 0, else 0,   d_n = m_n - m_{n-1}
    s_n   = s_{n-1} + a_n (v_n - s_{n-1}),  a_n = h_n / (h_n + TAU)
    eps_n = min(CAP, max(floor_j, c s_n))
    y_n   = m_n - clip(m_n - y_{n-1}, -eps_n, eps_n)

v is a reversal: the map went one way and came back. Noise reverses about every other
frame; a movement does not, and where it turns (a peak) its steps are near 0. So s, the
running mean of v (weight units), grows with the noise and barely with the motion: on a
face the tracker reads cleanly the band is the floor (the model's ``deadband``), on a
noisy one it widens, during speech as at rest. (The second difference |m_n - 2 m_{n-1} +
m_{n-2}| measures speech's accelerations as noise: at the same jitter it lagged 6-8 ms
more, docs/MODEL.md.) ``c`` is the model's ``noise_band`` (0 or absent: the fixed band).
A (re)start takes the map's value (y = m) and m_{n-1} = m_{n-2} = m; s is kept through a
restart (the same face came back) and is 0 after ``reset``. A smooth curve reverses only
where it turns, with steps near 0, at any frame rate: the contract's rate clause holds as
for the fixed band. CAP bounds the band where the tracker jumps and jumps back (a
glitch's reversal is large) or jitters past what a band should hold: a wider band would
hold real movement (map_weights.MAX_DEADBAND).
"""

from __future__ import annotations

import numpy as np

from faceclean.filters.one_euro import DT_MIN
from faceclean.learned.map_weights import MAX_DEADBAND

TAU = 1.0  # s: the noise estimate's time constant
CAP = MAX_DEADBAND  # weight units: the widest band


class Noise:
    """The band's state for S streams and M outputs: m_{n-1}, m_{n-2}, s (S, M) each."""

    def __init__(self, s: int, m: int) -> None:
        self.p1 = np.full((s, m), np.nan)
        self.p2 = np.full((s, m), np.nan)
        self.s = np.zeros((s, m))


def step(m: np.ndarray, y: np.ndarray, st: Noise, h: np.ndarray | float, floor: np.ndarray,
         c: float, rows: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """The output (S, M) for the map's value m (S, M) after the last output y (S, M), h s
    (S, 1) or a number; updates ``st``. ``rows`` (S,) bool: the streams that advance (the
    others keep their state; their output is m, which the caller discards)."""
    if rows is None:
        return _every(m, y, st, h, floor, c)
    new = Noise(0, 0)  # the usual frame's step on a copy, kept for ``rows`` only
    new.s, new.p1, new.p2 = st.s.copy(), st.p1, st.p2
    with np.errstate(invalid="ignore"):  # streams not started yet: NaN, not kept
        out = _every(m, y, new, h, floor, c)
    keep = rows[:, None]
    st.s = np.where(keep, new.s, st.s)
    st.p2 = np.where(keep, new.p2, st.p2)
    st.p1 = np.where(keep, new.p1, st.p1)
    return np.where(keep, out, m)


def _every(m: np.ndarray, y: np.ndarray, st: Noise, h: np.ndarray | float, floor: np.ndarray,
           c: float) -> np.ndarray:  # fmt: skip
    """``step`` for every stream advancing (the usual frame; the one place of the module
    equation in numpy), in place where it can be: 1.2 -> 0.5 us a stream at 1,024
    streams against a new array a pass."""
    d = m - st.p1
    d0 = st.p1 - st.p2
    turn = d * d0 < 0.0
    v = np.abs(d)
    np.minimum(v, np.abs(d0), out=v)
    v *= turn  # the reversal: 0 where the steps do not turn
    v -= st.s
    v *= h / (h + TAU)
    st.s += v  # s + a (v - s)
    eps = c * st.s
    np.maximum(eps, floor, out=eps)
    np.minimum(eps, CAP, out=eps)
    out = m - y
    np.clip(out, -eps, eps, out=out)
    np.subtract(m, out, out=out)
    st.p2, st.p1 = st.p1, m.copy()
    return out


def start(m: np.ndarray, st: Noise, rows: np.ndarray) -> None:
    """A (re)start of the streams ``rows`` (S,) bool: m_{n-1} = m_{n-2} = m (S, M)."""
    keep = rows[:, None]
    st.p1 = np.where(keep, m, st.p1)
    st.p2 = np.where(keep, m, st.p2)


def run(m: np.ndarray, h: np.ndarray, y0: np.ndarray, st: Noise, floor: np.ndarray,
        c: float) -> np.ndarray:  # fmt: skip
    """``step`` over a run of frames of one stream: m (N, M) the map's values, h (N,) s,
    y0 (M,) the output before the run; (N, M) outputs, ``st`` (one stream) as stepping
    leaves it. Compiled (filters/compiled.py) where numba is on, else frame by frame."""
    from faceclean.filters import compiled

    s, p1, p2 = st.s[0].copy(), st.p1[0].copy(), st.p2[0].copy()
    m = np.ascontiguousarray(m, np.float64)
    y = compiled.noise_band(m, h, y0, p1, p2, s, floor, c, TAU, CAP)
    if y is not None:
        st.s, st.p1, st.p2 = s[None], p1[None], p2[None]
        return y
    y, prev = np.empty_like(m), y0[None]  # without numba: the usual frame's step, in turn
    for n in range(len(m)):
        prev = y[n : n + 1] = _every(m[n : n + 1], prev, st, h[n], floor, c)
    return y


def whole(m: np.ndarray, t: np.ndarray, floor: np.ndarray, c: float) -> np.ndarray:
    """The band over one stream's frames m (N, M) at t (N,) s from a reset (the fits'
    view: map_features.predict): y_0 = m_0, then ``run``."""
    if len(m) < 2:
        return m.copy()
    st = Noise(1, m.shape[1])
    start(m[:1], st, np.ones(1, bool))
    y = np.empty_like(m)
    y[0] = m[0]
    h = np.maximum(np.diff(t), DT_MIN)  # s, as the runtime's usual frame takes it
    y[1:] = run(m[1:], h, m[0], st, floor, c)
    return y
