"""Quality measures of SPEC section 5: MSE, jitter ratio, lag, blink closure.

Every function takes a prediction and the truth at the same instants: times (N,) in
seconds, values (N, M). Rows where either side is missing (all NaN) are ignored, and so
are single NaN values. Timestamps may be irregular; derivatives use the real times.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.signal import find_peaks

from faceclean.animation import Animation
from faceclean.channel_map import ChannelMap
from faceclean.channels import canonical, channel_key
from faceclean.errors import FacecleanError

BLINK_CHANNELS = ("eyeBlinkLeft", "eyeBlinkRight")
BLINK_PROMINENCE = 0.3  # a true blink: a peak of eyeBlink* rising >= 0.3 above its surroundings
BLINK_WINDOW = 0.060  # s; the output's peak is looked for within +-60 ms of the true peak
LAG_RANGE = (-0.100, 0.200)  # s; delays searched (positive = output late)
LAG_COARSE = 0.005  # s; coarse grid step, refined to 1 ms, then a parabola


def _rows(times: np.ndarray, pred: np.ndarray, truth: np.ndarray):
    """(times, pred, truth) restricted to rows both sides carry, at increasing times."""
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    pred = np.asarray(pred, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    pred = pred.reshape(len(times), -1)
    truth = truth.reshape(len(times), -1)
    if pred.shape != truth.shape:
        raise FacecleanError(f"prediction {pred.shape} and truth {truth.shape} differ in shape")
    ok = np.isfinite(times) & ~np.isnan(pred).all(axis=1) & ~np.isnan(truth).all(axis=1)
    times, pred, truth = times[ok], pred[ok], truth[ok]
    # A repeated or backward timestamp carries no new instant: keep rows that advance time.
    keep = np.ones(len(times), bool)
    if len(times) > 1:
        keep[1:] = times[1:] > np.maximum.accumulate(times)[:-1]
    return times[keep], pred[keep], truth[keep]


def mse(pred: np.ndarray, truth: np.ndarray) -> float:
    """Mean squared error over all channels and frames (the paper's measure)."""
    err = (np.asarray(pred, dtype=np.float64) - np.asarray(truth, dtype=np.float64)) ** 2
    err = err[np.isfinite(err)]
    return float(err.mean()) if err.size else float("nan")


def _second_derivative(times: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N-2, M) second time-derivative on a non-uniform grid (three-point formula).

    x''[n] = 2 ((x[n+1]-x[n])/h1 - (x[n]-x[n-1])/h0) / (h0 + h1), h = the real dt.
    """
    h = np.diff(times)[:, None]  # (N-1, 1) s
    slope = np.diff(x, axis=0) / h  # (N-1, M) units/s
    return 2.0 * np.diff(slope, axis=0) / (h[1:] + h[:-1])


def jitter_ratio(times: np.ndarray, pred: np.ndarray, truth: np.ndarray) -> float:
    """Mean squared second time-derivative of ``pred`` over that of ``truth``.

    1.0 is ideal; raw tracker input is far above, an over-smoothed output below.
    Only values where both sides are finite count. Equal and motionless: 1.0;
    motionless truth and moving output: inf; fewer than 3 frames: NaN.
    """
    times, pred, truth = _rows(times, pred, truth)
    if len(times) < 3:
        return float("nan")
    dp = _second_derivative(times, pred)
    dt_ = _second_derivative(times, truth)
    ok = np.isfinite(dp) & np.isfinite(dt_)
    num = float(np.mean(dp[ok] ** 2)) if ok.any() else float("nan")
    den = float(np.mean(dt_[ok] ** 2)) if ok.any() else float("nan")
    if den == 0.0:
        return 1.0 if num == 0.0 else float("inf")
    return num / den


def interp_rows(times: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Linear interpolation of (N, M) values sampled at increasing times, at (K,) instants."""
    i = np.clip(np.searchsorted(times, at, side="right") - 1, 0, len(times) - 2)
    w = ((at - times[i]) / (times[i + 1] - times[i]))[:, None]
    return values[i] * (1.0 - w) + values[i + 1] * w


def lag_ms(times: np.ndarray, pred: np.ndarray, truth: np.ndarray) -> float:
    """The delay in ms that best aligns ``pred`` with ``truth`` (positive = output late).

    Minimises the MSE between pred(t + d) (linear interpolation in time) and truth(t)
    over d in LAG_RANGE: a 5 ms grid, then 1 ms around its best, then a parabola through
    the three best 1 ms points (sub-ms). The same truth instants are used for every d.
    NaN when the truth does not move or the clip is too short to compare.
    """
    times, pred, truth = _rows(times, pred, truth)
    if len(times) < 3 or not np.isfinite(truth).any():
        return float("nan")
    lo, hi = LAG_RANGE
    span = times[-1] - times[0]
    # Truth instants where pred(t + d) exists for every d searched; shrink d if the clip is short.
    scale = min(1.0, 0.5 * span / (hi - lo))
    lo, hi = lo * scale, hi * scale
    at_ok = (times >= times[0] - lo) & (times <= times[-1] - hi)
    t_eval, y_eval = times[at_ok], truth[at_ok]
    if len(t_eval) < 2 or np.nanstd(y_eval) == 0.0:
        return float("nan")
    pred_f = np.where(np.isfinite(pred), pred, np.nan)

    def cost(d: float) -> float:
        err = (interp_rows(times, pred_f, t_eval + d) - y_eval) ** 2
        return float(np.nanmean(err))

    coarse = np.arange(lo, hi + 1e-9, LAG_COARSE * scale)
    c = np.array([cost(d) for d in coarse])
    best = coarse[int(np.argmin(c))]
    fine_step = 0.001 * scale
    fine = best + fine_step * np.arange(-4, 5)
    fine = fine[(fine >= lo) & (fine <= hi)]
    f = np.array([cost(d) for d in fine])
    k = int(np.argmin(f))
    d = fine[k]
    if 0 < k < len(fine) - 1:  # parabola through the best point and its neighbours
        a, b, cc = f[k - 1], f[k], f[k + 1]
        curv = a - 2.0 * b + cc
        if curv > 0:
            d += 0.5 * fine_step * (a - cc) / curv
    return 1000.0 * float(d)


def blink_closure(
    times: np.ndarray, pred: np.ndarray, truth: np.ndarray, names: Sequence[str]
) -> float:
    """Mean over true blinks of (output peak / true peak); 1.0 is ideal (see blink_peaks)."""
    r = blink_peaks(times, pred, truth, names)
    return float(r.mean()) if r.size else float("nan")


def blink_peaks(
    times: np.ndarray, pred: np.ndarray, truth: np.ndarray, names: Sequence[str]
) -> np.ndarray:
    """(B,) output peak / true peak for each true blink.

    True blinks: peaks of the truth's eyeBlinkLeft / eyeBlinkRight (any spelling in
    ``names``) with prominence >= BLINK_PROMINENCE. The output peak is its maximum within
    +-BLINK_WINDOW s of the true peak. Empty when the truth holds no blink.
    """
    times, pred, truth = _rows(times, pred, truth)
    keys = [canonical(n) for n in names]
    ratios: list[np.ndarray] = []
    for ch in BLINK_CHANNELS:
        if ch not in keys:
            continue
        j = keys.index(ch)
        y, p = truth[:, j], pred[:, j]
        ok = np.isfinite(y)
        ty, y, p = times[ok], y[ok], p[ok]
        peaks, _ = find_peaks(y, prominence=BLINK_PROMINENCE)
        if not len(peaks):
            continue
        # (B, N) window mask around each true peak; output peak = masked max.
        near = np.abs(ty[None, :] - ty[peaks][:, None]) <= BLINK_WINDOW + 1e-9
        windowed = np.where(near & np.isfinite(p)[None, :], p[None, :], -np.inf)
        out_peak = windowed.max(axis=1)
        keep = np.isfinite(out_peak) & (y[peaks] > 0)
        ratios.append(out_peak[keep] / y[peaks][keep])
    return np.concatenate(ratios) if ratios else np.zeros(0)


def paired(pred: Animation, truth: Animation) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Columns of pred and truth matched by canonical name (exact name when unknown)."""
    if pred.n_frames != truth.n_frames:
        raise FacecleanError(
            f"prediction has {pred.n_frames} frames, truth {truth.n_frames}: "
            "they must be at the same instants"
        )
    names = list(dict.fromkeys(channel_key(n) for n in truth.names))  # truth order, once each
    pi, ti = ChannelMap(names, pred.names).src, ChannelMap(names, truth.names).src
    both = pi >= 0
    pi, ti, names = pi[both], ti[both], [n for n, b in zip(names, both, strict=True) if b]
    if not names:
        raise FacecleanError("prediction and truth share no channel")
    return pred.values[:, pi], truth.values[:, ti], names


def summary(pred: Animation, truth: Animation) -> dict[str, float]:
    """All four measures for one clip: keys mse, jitter_ratio, lag_ms, blink_closure.

    Channels are matched by canonical name; times are the truth's (both sides must be at
    the same instants, as a cleaner's output is at its input's).
    """
    p, y, names = paired(pred, truth)
    times, p, y = _rows(truth.times, p, y)
    return {
        "mse": mse(p, y),
        "jitter_ratio": jitter_ratio(times, p, y),
        "lag_ms": lag_ms(times, p, y),
        "blink_closure": blink_closure(times, p, y, names),
    }
