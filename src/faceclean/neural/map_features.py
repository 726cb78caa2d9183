"""A tracker map's causal features and its output on them, as the fits see them.

Per pair (``features``): the pre-filtered input u (the runtime's own One Euro, stepped as
the cleaner steps it), its resting level r (``rest``: the running minimum since reset, of
u smoothed with the config's ``rest_tau``, after its ``rest_warm``, climbing back at its
``rest_drift``), the truth y
and the detail e = x - u, (F, K) each; ``predict`` is the runtime's output on them
(learned/tracker_map.py, deadband and blink lift included) and ``score`` its MSE, jitter,
lag and blink closure. Every fit of neural/ (tracker_map.py, map_rises.py, blink_lift.py)
scores its candidates through these, so training sees what the cleaner computes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.datasets.paired import Pair
from faceclean.filters.one_euro import OneEuro
from faceclean.learned.formats import TRACKER_MAP
from faceclean.learned.map_weights import MapWeights


def channels(pairs: Sequence[Pair]) -> tuple[str, ...]:
    """The tracker's channels that are ARKit channels, in canonical order (inputs = outputs)."""
    have = set()
    for p in pairs:
        _, present = p.tracked.arkit(ARKIT52)
        have |= {n for n, ok in zip(ARKIT52, present, strict=True) if ok}
    return tuple(n for n in ARKIT52 if n in have)


def blank(names: Sequence[str], hidden: int, pre: tuple[float, float, float], rest: bool,
          prefilter: bool = True, deadband: float = 0.0) -> MapWeights:  # fmt: skip
    """An identity map (y = u) of the right shapes: the start of every fit."""
    k, h = len(names), hidden
    arrays = {
        "min_cutoff": np.full(k, pre[0]),
        "beta": np.full(k, pre[1]),
        "d_cutoff": np.full(k, pre[2]),
        "mu": np.zeros(2 * k),
        "sd": np.ones(2 * k),
        "w1": np.zeros((h, 2 * k)),
        "b1": np.zeros(h),
        "w2": np.zeros((k, h)),
        "b2": np.zeros(k),
        "a": np.eye(k),
        "b": np.zeros((k, k)),
        "c": np.zeros(k),
        "lift_gain": np.zeros(k),
        "lift_knee": np.zeros(k),
    }
    config = {"format": TRACKER_MAP, "inputs": list(names), "outputs": list(names),
              "hidden": h, "rest": rest, "prefilter": prefilter}  # fmt: skip
    if deadband:
        config["deadband"] = deadband
    return MapWeights(config, arrays)


class Feature(NamedTuple):
    """One pair's causal features over its valid frames: times t (F,) s, the pre-filtered
    input u, the resting level r, the truth y and the detail e = x - u (raw input minus
    pre-filtered), (F, K) each."""

    t: np.ndarray
    u: np.ndarray
    r: np.ndarray
    y: np.ndarray
    e: np.ndarray


def features(w: MapWeights, pairs: Sequence[Pair]) -> list[Feature]:
    """Per pair its Feature. u comes from the runtime's own One Euro, stepped as the
    cleaner steps it (its compiled run: the same bits)."""
    from faceclean.filters import compiled

    compiled.enable()  # a fit cleans every pair once per candidate pre-filter
    names, a = w.inputs, w.arrays
    out = []
    for p in pairs:
        pre = OneEuro(names=names, min_cutoff=a["min_cutoff"].tolist(),
                      beta=a["beta"].tolist(), d_cutoff=a["d_cutoff"].tolist())  # fmt: skip
        x = p.tracked.arkit(names)[0]
        y = p.truth.arkit(names)[0]
        valid = ~np.isnan(x).all(axis=1)
        t, x, y = p.tracked.times[valid], np.nan_to_num(x[valid]), y[valid]
        # clean: reset, then step every frame
        u = pre.clean(Animation(t, x, names)).values if w.config["prefilter"] and len(t) else x
        r = rest(t, u, *w.rest)
        ok = ~np.isnan(y).any(axis=1)
        out.append(Feature(t[ok], u[ok], r[ok], y[ok], x[ok] - u[ok]))
    return out


def rest(t: np.ndarray, u: np.ndarray, tau=0.0, warm=0.0, drift=0.0) -> np.ndarray:
    """(F, K) the runtime's rest (learned/tracker_map.py ``_rest``) of one stream whose
    every frame advances, times t (F,) s: r = min(r + drift h, v), v += (1 - exp(-h / tau))
    (u - v) (v = u for tau 0), and r = v = u while t - t0 <= warm; tau and warm s, drift
    weight/s, each a number or one per input (K,)."""
    if not len(t):
        return u.copy()
    sets = np.stack([np.broadcast_to(np.asarray(a, np.float64), (u.shape[1],))
                     for a in (tau, warm, drift)], axis=1)  # (K, 3)  # fmt: skip
    if np.ptp(sets, axis=0).any():  # per input: each distinct setting's columns alone
        r = np.empty_like(u)
        for s in {tuple(map(float, row)) for row in sets}:
            cols = np.flatnonzero((sets == s).all(axis=1))
            r[:, cols] = rest(t, u[:, cols], *s)
        return r
    tau, warm, drift = map(float, sets[0])
    k = int(np.sum(t - t[0] <= warm)) if warm > 0 else 0  # frames of the warm-up: r = v = u
    from faceclean.filters.one_euro import DT_MIN

    h = np.maximum(np.diff(t), DT_MIN)  # (F - 1,) s
    v = u
    if tau > 0:
        v = u.copy()
        for n in range(max(k, 1), len(t)):  # the runtime's order: v + a (u - v)
            v[n] = v[n - 1] + -np.expm1(-h[n - 1] / tau) * (u[n] - v[n - 1])
    r = u.copy()
    if k < len(t):  # then min(r + drift h, v) on, from the last frame's r
        first = max(k - 1, 0)  # the frame of start's first row
        start = v[k:] if k == 0 else np.concatenate([u[k - 1 : k], v[k:]])
        # r_n - C_n = min(r_n-1 - C_n-1, v_n - C_n), C the climb so far: an accumulate
        climb = drift * np.concatenate([[0.0], np.cumsum(h)])[first:, None]  # (F - first, 1)
        low = np.fmin.accumulate(start - climb, axis=0) + climb
        r[k:] = low[-(len(t) - k) :]
    return r


def low_pass(x: np.ndarray, t: np.ndarray, tau: float) -> np.ndarray:
    """(F, L) the runtime's low-pass of the lift's raw inputs x (F, L) at times t (F,) s:
    p_0 = x_0, p_n = p_n-1 + a (x_n - p_n-1), a = h / (h + tau) (learned/tracker_map.py)."""
    from scipy.signal import lfilter

    from faceclean.filters.one_euro import DT_MIN

    if len(x) < 2:
        return x.copy()
    a = np.maximum(np.diff(t), DT_MIN)
    a = a / (a + tau)  # (F - 1,)
    if np.ptp(a) < 1e-12:  # a steady rate: one linear filter, from p_0 = x_0
        a0 = float(a[0])
        rest = lfilter([a0], [1.0, a0 - 1.0], x[1:], axis=0, zi=(1 - a0) * x[:1])[0]
        return np.concatenate([x[:1], rest])
    p = x.copy()
    for n in range(1, len(x)):
        p[n] = p[n - 1] + a[n - 1] * (x[n] - p[n - 1])
    return p


def own_inputs(w: MapWeights) -> np.ndarray:
    """(M,) each output's input of the same name, -1 for none."""
    return np.array([w.inputs.index(o) if o in w.inputs else -1 for o in w.outputs])


def set_linear(w: MapWeights, coef: np.ndarray, c: np.ndarray, d: np.ndarray | None = None
                ) -> None:  # fmt: skip
    k = len(w.inputs)
    w.arrays["a"], w.arrays["c"] = coef[:, :k], c
    w.arrays["b"] = coef[:, k:] if coef.shape[1] > k else np.zeros((len(c), k))
    w.arrays["detail"] = np.zeros(len(c)) if d is None else d


def score(w: MapWeights, feats, lag: bool = False, closure: bool = False) -> tuple[float, ...]:
    """(MSE, jitter ratio vs the truth[, lag ms][, blink closure, blinks' MSE x raw]) of the
    map over per-pair features, from one prediction per pair; closure is the mean over
    every true blink, the blinks' MSE x raw that of the blink outputs against their raw
    inputs (x = u + e) over every frame."""
    from faceclean.evaluation.metrics import (  # numpy only
        BLINK_CHANNELS,
        blink_peaks,
        jitter_ratio,
        lag_ms,
    )

    own = own_inputs(w)
    eyes = [j for j, o in enumerate(w.outputs) if o in BLINK_CHANNELS and own[j] >= 0]
    sq, n, jit, lags, peaks, blinks = 0.0, 0, [], [], [], np.zeros(2)
    for t, u, r, y, e in feats:
        pred = predict(w, u, r, e, t)
        sq, n = sq + float(((pred - y) ** 2).sum()), n + y.size
        if len(t) > 3:
            jit.append(jitter_ratio(t, pred, y))
            if lag:
                lags.append(lag_ms(t, pred, y))
        if closure:
            peaks.append(blink_peaks(t, pred, y, w.outputs))
            raw = (u + e)[:, own[eyes]]
            blinks += (((pred[:, eyes] - y[:, eyes]) ** 2).sum(), ((raw - y[:, eyes]) ** 2).sum())
    mean = lambda v: float(np.nanmean(v)) if np.isfinite(v).any() else float("nan")  # noqa: E731
    out = (sq / max(n, 1), mean(jit)) + ((mean(lags),) if lag else ())
    if not closure:
        return out
    close = mean(np.concatenate(peaks)) if peaks else float("nan")
    return out + (close, blinks[0] / blinks[1] if blinks[1] > 0 else float("nan"))


def predict(w: MapWeights, u: np.ndarray, r: np.ndarray, e: np.ndarray | None = None,
            t: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """The runtime's output for one pair's features (F, K), deadband included (the band
    widened by the noise needs the frames' times t (F,) s)."""
    a = w.arrays
    lin = u @ a["a"].T + a["c"]
    rest = (u - r) if w.config["rest"] else np.zeros_like(u)
    lin = lin + rest @ a["b"].T
    d = a.get("detail", np.zeros(0)) * float(w.config.get("detail_scale", 1.0))
    if e is not None and d.any():  # the detail, on each output's own input
        on = np.flatnonzero(d)
        lin[:, on] += d[on] * e[:, own_inputs(w)[on]]
    if w.config["hidden"]:
        z = (np.concatenate([u, rest], axis=1) - a["mu"]) / a["sd"]
        lin = lin + np.tanh(z @ a["w1"].T + a["b1"]) @ a["w2"].T + a["b2"]
    m = np.clip(lin, 0.0, 1.0)
    lo = np.flatnonzero(a.get("lift_gain", np.zeros(0)) > 0)
    if len(lo):  # the lift: m_j = max(m_j, clip(l / max(1, top), 0, 1)), l = g (p_j - r_j - k)
        j = own_inputs(w)[lo]  # each lifted output's own input
        if e is None or t is None:
            raise ValueError("a blink lift needs the raw inputs' detail e and the times")
        p = low_pass((u + e)[:, j], t, w.lift_tau)
        rise = a["lift_gain"][lo] * (p - r[:, j] - a["lift_knee"][lo])
        if w.config.get("lift_top"):  # the largest lift so far, from the pair's first frame
            rise = rise / np.maximum(np.maximum.accumulate(rise, axis=0), 1.0)
        m[:, lo] = np.maximum(m[:, lo], np.clip(rise, 0.0, 1.0))
    band = np.broadcast_to(np.asarray(w.config.get("deadband", 0.0), np.float64), m.shape[1:])
    c = float(w.config.get("noise_band", 0.0))
    if c > 0:
        if t is None:
            raise ValueError("a band widened by the noise needs the frames' times")
        from faceclean.learned import band as noise

        return noise.whole(m, t, np.ascontiguousarray(band), c)
    if not band.any() or len(m) < 2:
        return m
    from faceclean.filters import compiled

    y = compiled.deadband(m, band)  # the loop below, compiled (numba), when it is on
    if y is not None:
        return y
    y = m.copy()  # y[n] = m[n] - clip(m[n] - y[n-1], -eps, eps), frame after frame
    for i in range(1, len(m)):
        y[i] -= np.clip(m[i] - y[i - 1], -band, band)
    return y
