"""The tracker map: a learned cleaner for one tracker's output, trained on real pairs.

A tracker such as MediaPipe under-reads blinks, reads channels at the wrong scale, mixes
neighbours and sits off zero at rest: a filter cannot fix levels, a map fitted on
(tracked, truth) pairs can. One step, per stream, input x (K,), dt s after the last frame:

    u  = OneEuro(x)                     tuned pre-filter (min_cutoff, beta, d_cutoff), so
                                        the map sees the tracker's signal, not its noise
    r  = min(r + rho h, v)              the stream's resting level so far (since reset):
                                        v = u, or with ``rest_tau`` u smoothed over that
                                        many s (v += (1 - exp(-h / tau)) (u - v)); with
                                        ``rest_warm``, r = v = u for that many s after
                                        the stream's first frame (every rise 0); it
                                        climbs back toward v at ``rest_drift`` rho
                                        weight/s at most (0: the running minimum of v);
                                        a face's own reading r0 adds L max(0, r - r0)
                                        to m (``set_rest_reading``)
    z  = [(u - mu_u) / sd_u, (u - r) / sd_r]                                     (2K,)
    m  = clip(A u + B (u - r) + c + d (x - u)_own + W2 tanh(W1 z + b1) + b2, 0, 1)  (M,)
    m_j = max(m_j, clip(l_j / max(1, T_j), 0, 1))  a lift, where g_j > 0 (blinks):
                                        l_j = g_j (p_j - r_j - k_j), T_j its largest value
                                        so far (with ``lift_top``; else T_j = 1), p_j the
                                        raw x_j low-passed: p += h / (h + tau) (x - p)
    y  = m - clip(m - y_prev, -eps, eps)     a deadband (backlash) of eps per output, with
                                        ``noise_band`` c > 0 widened to c x the stream's
                                        own noise where that is more (learned/band.py)

``A u + B (u - r) + c`` is linear over all inputs and their rise above the stream's rest,
which takes each face's own resting reading off, where identities differ most (B = 0, no
hidden layer, no pre-filter: the per-channel ridge baseline). ``d (x - u)_own`` is the
detail: output j adds d_j times what the pre-filter took off its own input, so the timing
comes from the channel's raw input and the noise of the other 50 stays filtered. The
deadband (``deadband``, 0 if absent) holds the output while the map's value stays within
eps of it: a still face's noise moves nothing, a movement passes with a lag of eps / speed.
The lift restores a peak a least-squares map pulls toward the mean (a closing lid): past a
knee k of its own rise, an output is at least the rise times a gain g (0 at rest), read
through a plain low-pass (``lift_cutoff``, 4 Hz: One Euro's slope differs between frame
rates); with ``lift_top`` the largest so far reaches 1. The optional hidden layer
(``hidden`` > 0) overfits the pairs we have: the shipped map is linear (docs/MODEL.md).
It cannot invent motion: m is a function of (u, r, x - u); on a still face u converges to
x, the detail to 0, r is constant, so m and y converge; a missing frame holds u and so y.
The rest is smoothed and drifts: the minimum of a smoothed reading finds a face's rest,
not its noise's lowest dip, and a drift forgets a dip while a held expression keeps all
but rho a second (docs/MODEL.md 8-19). A guided calibration sets a face's rest reading
and own-rise outputs (``set_rest_reading``, ``set_own_rise``).

Time rules are filters/base.py's for every column (``frame_rules``): a missing frame or an
old time repeats the last output, a gap restarts the filter (the rest is kept: the same
face came back), a bad input holds its filtered value. Unknown input columns pass through;
model inputs the frame lacks read 0; outputs it has no column for are not written.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from faceclean.channel_map import ChannelMap, columns, span
from faceclean.errors import FacecleanError
from faceclean.filters.base import MAX_ABS, MIN_DT, Stepper, frame_rules
from faceclean.filters.one_euro import DT_MIN, OneEuro, alpha
from faceclean.learned import band as noise
from faceclean.learned.map_weights import MAX_DETAIL as MAX_DETAIL  # neural/map_groups.py's
from faceclean.learned.map_weights import MAX_DRIFT, MAX_NOISE, MapWeights, column_setting, own_rise

if TYPE_CHECKING:
    from faceclean.animation import Animation


class TrackerMap(Stepper):
    """Tracker map cleaner (module docstring). ``min_cutoff``/``beta``/``d_cutoff`` (Hz)
    replace the model's pre-filter settings (scalars, or one per model input); ``detail``
    in [0, 1] how much of the pre-filter's lag the map takes back (1: all), ``rest_drift``
    how fast the rest climbs back (weight/s; 0: held expressions kept), each a scalar or
    one per column of ``names``; ``noise_band`` how far the band widens over the noise."""

    name = "tracker-map"
    PER_CHANNEL = ("detail", "rest_drift")

    def __init__(
        self,
        *,
        model: str | os.PathLike | None = None,
        weights: MapWeights | None = None,
        min_cutoff: float | Sequence[float] | None = None,
        beta: float | Sequence[float] | None = None,
        d_cutoff: float | Sequence[float] | None = None,
        detail: float | Sequence[float] | None = None,
        rest_drift: float | Sequence[float] | None = None,
        noise_band: float | None = None,
        names: Sequence[str] | None = None,
    ) -> None:
        if weights is None:
            if model is None:
                raise FacecleanError("tracker-map needs a model file (--model FILE.npz)")
            weights = MapWeights.load(model)
        self._base, self._own = weights, ()
        self._kw = {"min_cutoff": min_cutoff, "beta": beta, "d_cutoff": d_cutoff, "detail": detail,
                    "rest_drift": rest_drift, "noise_band": noise_band, "names": names}  # fmt: skip
        self._build(weights, **self._kw)
        self.set_rest_reading(None)  # (K,) r0 and (K, M+L) L: none until a face's is set
        self.reset()

    def _build(self, w, min_cutoff, beta, d_cutoff, detail, rest_drift, noise_band, names):
        """The constants of ``w`` and the user's settings; no stream state (``reset``)."""
        self.weights = w
        self.__dict__.pop("_kind", None)  # the compiled take's constants (map_take) go too
        self.names = tuple(names) if names is not None else w.inputs
        self._in = ChannelMap(w.inputs, self.names)  # model input j <- column src[j]
        self._out = ChannelMap(w.outputs, self.names)  # model output j -> column src[j]
        c = len(self.names)
        self.detail = column_setting("detail", detail, w.config.get("detail_scale", 1.0), c)
        scale = np.full(len(w.outputs), float(w.config.get("detail_scale", 1.0)))  # (M,)
        scale[self._out.have] = np.broadcast_to(self.detail, (len(self.names),))[self._out.cols]
        a = dict(w.arrays, detail=w.arrays["detail"] * scale)
        self.prefilter = bool(w.config.get("prefilter", True))
        self.rest = bool(w.config.get("rest", True))
        pre = {"min_cutoff": a["min_cutoff"], "beta": a["beta"], "d_cutoff": a["d_cutoff"]}
        for key, value in (("min_cutoff", min_cutoff), ("beta", beta), ("d_cutoff", d_cutoff)):
            if value is not None:
                pre[key] = value
        pre = {k: np.asarray(v, np.float64).tolist() for k, v in pre.items()}
        self.pre = OneEuro(names=w.inputs, **pre)  # its checked settings; stepped inline
        self._hidden = int(w.config["hidden"]) > 0
        # The usual frame's constants (``_usual``): y = u (A + B)' - r B' + c, the One
        # Euro cut-offs as time constants tau = 1 / (2 pi f) s.
        b = a["b"] if self.rest else np.zeros_like(a["b"])
        # The lift as L more columns of the same products: -g r_j - g k, + g p_j apart.
        self._lo = np.flatnonzero(a["lift_gain"] > 0)  # (L,) lifted outputs
        self._li = np.array([w.inputs.index(w.outputs[j]) for j in self._lo], dtype=np.intp)
        self._lg, m = a["lift_gain"][self._lo], len(w.outputs)
        self._lift_tau = w.lift_tau  # s, the low-pass of the lift's raw input
        lift = np.zeros((len(w.inputs), len(self._lo)))
        lift[self._li, np.arange(len(self._lo))] = self._lg
        # The detail d_j (x_j - u_j): -d_j u_j in the matrix on u, D (K, M), d_j at the input
        # of output j's name; + d_j x_j elementwise, outputs ``_do`` from inputs ``_di``.
        self._d = a["detail"]  # (M,) the gains as scaled
        self._do = np.flatnonzero(self._d)  # (N,) outputs with a detail
        self._di = np.array([w.inputs.index(w.outputs[j]) for j in self._do], dtype=np.intp)
        detail = np.zeros((len(w.inputs), m))
        detail[self._di, self._do] = a["detail"][self._do]
        # (x D was a product of a diagonal: its other terms add 0, the same bits.) Where
        # the columns run, a slice; None where they are all of them (MediaPipe's).
        self._dd = self._d[self._do]  # (N,)
        self._dos = columns(self._do, m + len(self._lo))
        self._dis = columns(self._di, len(w.inputs))
        ab = (a["a"] + b).T - detail
        self._ab = np.ascontiguousarray(np.concatenate([ab, 0 * lift], axis=1))  # (K, M+L)
        self._nb = np.ascontiguousarray(np.concatenate([-b.T, -lift], axis=1))  # (K, M+L)
        self._c = np.concatenate([a["c"], -self._lg * a["lift_knee"][self._lo]])  # (M+L,)
        self._m_cols = m
        self._tau_d = 1.0 / (2.0 * np.pi * np.broadcast_to(self.pre.d_cutoff, (len(w.inputs),)))
        self._mc2pi = 2.0 * np.pi * np.broadcast_to(self.pre.min_cutoff, (len(w.inputs),))
        self._beta2pi = 2.0 * np.pi * np.broadcast_to(self.pre.beta, (len(w.inputs),))
        self._direct = self._in.identity and self._out.identity  # columns = inputs = outputs
        # an ARKit take's columns: the inputs and the outputs a run of columns, read and
        # written as a view (no gather, no scatter); None: by index
        self._xs = span(self._in.src)
        self._ys = span(self._out.src)
        band = np.asarray(w.config.get("deadband", 0.0), np.float64)
        c_band = w.config.get("noise_band", 0.0) if noise_band is None else noise_band  # one
        self.noise_band = self._noise_c = column_setting("noise_band", c_band, 0, 0, MAX_NOISE)
        on = band.any() or self._noise_c > 0
        self._band = np.broadcast_to(band, (len(w.outputs),)).copy() if on else None
        eps = self._band if self._band is None or np.ptp(self._band) else float(self._band[0])
        self._eps = None if eps is None else (-eps, eps)  # ``_usual``'s; one number clips faster
        k = len(w.inputs)
        tau, warm, drift = w.rest  # (K,) each: smoothing s, warm-up s, drift weight/s
        shown = np.zeros(c)  # (C,) the model's drift by column (0 where no input reads one)
        shown[self._in.cols] = drift[self._in.have]
        self.rest_drift = column_setting("rest_drift", rest_drift, shown, c, MAX_DRIFT)
        drift = drift.copy()  # (K,) the setting's, on each input read from a column
        drift[self._in.have] = np.broadcast_to(self.rest_drift, (c,))[self._in.cols]
        self._rest_smooth = tau > 0  # (K,) inputs whose rest is smoothed; the others: v = u
        self._rest_plain = ~self._rest_smooth if not self._rest_smooth.all() else None  # (K,)
        self._rest_rate = np.divide(1.0, tau, out=np.full(k, np.inf), where=tau > 0)  # 1/s
        self._smoothed = bool(self._rest_smooth.any())  # any input's rest smoothed
        self._rest_warm = warm.copy() if (warm > 0).any() else None
        self._rest_warm_max = float(warm.max())
        self._rest_drift = drift  # (K,) weight/s
        self._drift = drift if drift.any() else None  # none: r + 0 not computed
        self._lift_top = bool(w.config.get("lift_top", False)) and len(self._lo) > 0

    def set_own_rise(self, outputs: Sequence[str] = ()) -> None:
        """``outputs`` read as their own rise alone (``map_weights.own_rise``); (): none."""
        if tuple(outputs) != self._own:  # the same outputs: nothing to rebuild
            self._own = tuple(outputs)
            self._build(own_rise(self._base, outputs), **self._kw)
            self.set_rest_reading(*self._reading)

    def set_rest_reading(self, reading: dict[str, float] | None, outputs: Sequence[str] = ()):
        """A face's reading at rest r0 of some inputs (u over a guided calibration's rests):
        ``outputs`` rise from min(r, r0), m += L max(0, r - r0), L = B there; None: none."""
        self._ceil, self._lvl, self._reading = None, None, (reading, tuple(outputs))
        if not reading or not self.rest:
            return
        r0 = np.array([float(reading.get(n, np.inf)) for n in self.weights.inputs])  # (K,)
        on = np.isin(self.weights.outputs, list(outputs))  # (M,); r0 inf: max(0, r - inf) = 0
        lvl = np.zeros_like(self._nb)  # (K, M+L): the lift's columns take none
        lvl[:, : self._m_cols] = -self._nb[:, : self._m_cols] * on * np.isfinite(r0)[:, None]
        self._ceil, self._lvl = (r0, lvl) if lvl.any() else (None, None)

    def reset(self) -> None:
        self._y: np.ndarray | None = None  # (S, M) last output; the rest is set with it

    def step(self, frame: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        x = np.array(frame, dtype=np.float64, ndmin=1)
        single = x.ndim == 1
        x = x.reshape(1, -1) if single else x
        s, k = len(x), len(self.weights.inputs)
        tt = np.array(t, dtype=np.float64, ndmin=1)  # (S,) s (broadcast_to costs 4 us)
        tt = tt if tt.shape == (s,) else np.broadcast_to(tt, (s,))
        if self._y is not None and self._y.shape == x.shape:
            out = self._usual(x, tt)
            if out is not None:
                return out[0].copy() if single else out.copy()
        if self._y is None or self._y.shape != x.shape:
            self._y = np.full_like(x, np.nan)  # (S, M) last output
            self._t = np.full(s, np.nan)  # (S,) s, time of the last accepted frame
            self._u = np.full((s, k), np.nan)  # (S, K) pre-filtered input
            self._edx = np.zeros((s, k))  # (S, K) One Euro's slope, weight/s
            self._r = np.full((s, k), np.nan)  # (S, K) resting level so far
            self._v = np.full((s, k), np.nan)  # (S, K) u smoothed for the rest (rest_tau)
            self._t0 = np.full(s, np.nan)  # (S,) s, the stream's first frame (rest_warm)
            self._rest_h, self._rest_f, self._warm_over = None, None, False  # h, factor; warm
            self._m = np.full((s, len(self.weights.outputs)), np.nan)  # (S, M) map's output
            self._top = np.full((s, len(self._lo)), -np.inf)  # (S, L) largest lift so far
            self._lp = np.full((s, len(self._lo)), np.nan)  # (S, L) the lift's low-pass
            self._noise = noise.Noise(s, len(self.weights.outputs))  # the band's noise
        bad = ~(np.abs(x) <= MAX_ABS)  # rule 2 for every column, passthrough ones too
        missing = bad.all(axis=1) | ~np.isfinite(tt)  # rule 1
        if bad.any():
            x = np.where(bad, np.nan_to_num(self._y, nan=0.0), x)
        dt = tt - self._t
        start, advance = frame_rules(missing, dt, self.pre.max_gap)
        moved = start | advance  # the rest hold: the last output (rules 1, 4)
        xi = self._in_matrix(x)
        held = self._in_matrix(bad.astype(np.float64)) > 0 if bad.any() else None  # (S, K)
        if held is not None:  # a bad input holds its filtered value (0 before any): never
            xi = np.where(held, np.nan_to_num(self._u, nan=0.0), xi)  # the output fed back
        u = self._u
        every = bool(advance.all())  # the usual frame: no merge of old and new rows
        if self.prefilter and (every or advance.any()):  # One Euro (filters/one_euro.py)
            h = np.maximum(dt if every else np.where(advance, dt, 1.0), DT_MIN)[:, None]  # s
            edx = self._edx + alpha(self.pre.d_cutoff, h) * ((xi - u) / h - self._edx)
            cut = self.pre.min_cutoff + self.pre.beta * np.abs(edx)
            new = u + alpha(cut, h) * (xi - u)
            u = new if every else np.where(advance[:, None], new, u)
            self._edx = edx if every else np.where(advance[:, None], edx, self._edx)
        elif not self.prefilter:
            u = xi if every else np.where(advance[:, None], xi, u)
        if start.any():  # rule 3: the filter restarts from the frame
            u = np.where(start[:, None], xi, u)
            self._edx = np.where(start[:, None], 0.0, self._edx)
        self._u = u
        if len(self._lo):  # the lift's low-pass p of its raw input, restarting with u
            h = np.maximum(np.where(advance, dt, 1.0), DT_MIN)[:, None]  # s
            p = self._lp + h / (h + self._lift_tau) * (xi[:, self._li] - self._lp)
            p = np.where(start[:, None], xi[:, self._li], p)
            self._lp = p if moved.all() else np.where(moved[:, None], p, self._lp)
        self._rest(u, dt, start, advance, tt)
        if held is not None and len(self._do):  # a held value has no detail
            xi = np.where(held, u, xi)
        y = self._map(u, moved, xi)
        if self._noise_c > 0:  # the band widened by the noise (learned/band.py)
            go = advance & ~start
            h = np.maximum(np.where(go, dt, 1.0), DT_MIN)[:, None]  # s
            y_band = noise.step(y, self._m, self._noise, h, self._band, self._noise_c, go)
            noise.start(y, self._noise, start)
            y = y_band
        elif self._band is not None:  # the deadband; a (re)start takes the map's value
            d = np.clip(y - self._m, -self._band, self._band)
            y = y - np.where(start[:, None] | np.isnan(d), 0.0, d)
        self._m = y if moved.all() else np.where(moved[:, None], y, self._m)
        out = x.copy()
        out[:, self._out.cols] = y[:, self._out.have]
        if not moved.all():
            out = np.where(moved[:, None], out, self._y)
        self._t = np.where(moved, tt, self._t)
        self._y = out
        return out[0].copy() if single else out.copy()

    def _usual(self, x: np.ndarray, tt: np.ndarray) -> np.ndarray | None:
        """The usual frame in fewer, fused steps (the cost of one stream is the count of
        numpy calls): every stream present, finite and within MAX_ABS, every one advancing
        (MIN_DT < dt <= max_gap), a pre-filter and no hidden layer. The same numbers as the
        general path (tests/learned/test_tracker_map.py); None: take the general path.
        x (S, columns) is ``step``'s own copy: the output is written into it. Each
        elementwise step in place is the same operation on the same operands as its
        expression (tests/learned/test_map_step.py: the same bits)."""
        if not self.prefilter or self._hidden or not np.abs(x).max() <= MAX_ABS:
            return None  # (NaN fails the test too)
        dt = tt - self._t  # (S,) s
        lo, hi = (dt[0], dt[0]) if len(dt) == 1 else (dt.min(), dt.max())
        if not (lo > MIN_DT and hi <= self.pre.max_gap):
            return None
        if self._rest_warm is not None and not self._warm_over:
            if not (tt - self._t0 > self._rest_warm_max).all():
                return None  # a stream's first rest_warm s: the general path (r = u)
            self._warm_over = True  # for good: accepted times only increase (filters/base.py)
        xs = self._xs
        xi = x[:, xs] if xs is not None else self._in_matrix(x)  # (S, K), a view where it runs
        h = np.maximum(dt, DT_MIN)[:, None] if lo != hi else max(float(lo), DT_MIN)  # s
        u, edx = self._u, self._edx
        e = xi - u  # (S, K)
        # One Euro: edx += a_d (e / h - edx), a = 1 / (1 + tau / h) = h / (h + tau)
        a = h + self._tau_d
        np.divide(h, a, out=a)
        q = e / h
        q -= edx
        q *= a
        edx += q
        g = np.abs(edx)  # g = h (2 pi mc + 2 pi beta |edx|): 2 pi f h
        g *= self._beta2pi
        g += self._mc2pi
        g *= h
        q = g + 1.0
        np.divide(g, q, out=q)
        q *= e
        u += q  # u += g / (1 + g) e
        if len(self._lo):  # the lift's low-pass: p += h / (h + tau) (x - p)
            self._lp += h / (h + self._lift_tau) * (xi[:, self._li] - self._lp)
        if self._smoothed:  # v += (1 - exp(-h / tau)) (u - v)
            if not (isinstance(h, float) and h == self._rest_h):  # (K,) again for a new h
                self._rest_f = -np.expm1(-h * self._rest_rate)
                self._rest_h = h if isinstance(h, float) else None  # a float, or none kept
            q = u - self._v
            q *= self._rest_f
            self._v += q
            if self._rest_plain is not None:  # inputs with no smoothing: v = u (one call)
                np.copyto(self._v, u, where=self._rest_plain)
        if self._drift is not None:  # r = min(r + rho h, v)
            self._r += self._drift * h
        np.minimum(self._r, self._v if self._smoothed else u, out=self._r)  # (finite once started)
        y = u @ self._ab  # (S, M+L)
        y += self._r @ self._nb
        if self._lvl is not None:  # a face's own rest reading (``set_rest_reading``)
            q = self._r - self._ceil
            q.clip(0.0, None, out=q)
            y += q @ self._lvl
        if len(self._do):  # the detail: + d (x - u), the -d u being in _ab
            q = (xi if self._dis is None else xi[:, self._dis]) * self._dd
            if self._dos is None:
                y += q
            else:
                y[:, self._dos] += q
        y += self._c
        if len(self._lo):
            y[:, self._m_cols :] += self._lp * self._lg
        if self._lift_top:  # the lift's top: l / max(1, the largest l so far)
            lift = y[:, self._m_cols :]
            np.maximum(self._top, lift, out=self._top)
            lift /= np.maximum(self._top, 1.0)
        y.clip(0.0, 1.0, out=y)  # np.clip's ufunc, without its wrapper
        if len(self._lo):  # the lift: m_j = max(m_j, its lift column)
            m = self._m_cols
            lifted = np.maximum(y[:, self._lo], y[:, m:])
            y = y[:, :m].copy()  # contiguous: the steps below run faster on it
            y[:, self._lo] = lifted
        band = self._band
        if self._noise_c > 0:  # the band widened by the noise (learned/band.py)
            y = noise.step(y, self._m, self._noise, h, band, self._noise_c)
            band = None
        if band is not None:  # the deadband: y = m - clip(m - y_prev, -eps, eps)
            d = y - self._m
            d.clip(*self._eps, out=d)
        out = y if self._direct else x  # (x: ``step``'s own copy, its columns written)
        if self._direct or self._ys is None:
            if band is not None:
                y -= d
            if not self._direct:
                out[:, self._out.cols] = y[:, self._out.have]
        elif band is not None:  # the run of output columns: written in place, a view
            y = np.subtract(y, d, out=x[:, self._ys])
        else:
            x[:, self._ys] = y
        self._m = y
        self._t = tt.copy()
        self._y = out
        return out

    def _rest(self, u, dt, start, advance, tt) -> None:
        """The rest r (S, K) after this frame (module docstring): min(r, v) on the rows
        that moved, NaN-aware (a stream's first frame sets it); v restarts from u where the
        filter does; r = v = u in a stream's first ``rest_warm`` s."""
        moved = start | advance
        v = u
        if self._smoothed:
            h = np.maximum(np.where(advance, dt, 1.0), DT_MIN)[:, None]  # s
            v = self._v + -np.expm1(-h * self._rest_rate) * (u - self._v)  # exact at any rate
            v = np.where(start[:, None] | np.isnan(v) | ~self._rest_smooth, u, v)
            self._v = v if moved.all() else np.where(moved[:, None], v, self._v)
        r = self._r
        if self._drift is not None:  # climbs rho h on a frame that advances, h s
            r = r + self._drift * np.where(advance, np.maximum(dt, DT_MIN), 0.0)[:, None]
        low = np.fmin(r, v)  # NaN-aware: the first frame sets it
        if self._rest_warm is not None:
            self._t0 = np.where(moved & np.isnan(self._t0), tt, self._t0)
            warm = (tt - self._t0)[:, None] <= self._rest_warm  # (S, K)
            low = np.where(warm, u, low)
            if self._smoothed:  # v starts from u when the warm-up ends
                self._v = np.where(warm & moved[:, None], u, self._v)
        self._r = low if moved.all() else np.where(moved[:, None], low, self._r)

    def _in_matrix(self, x: np.ndarray) -> np.ndarray:
        xi = np.zeros((len(x), len(self.weights.inputs)))
        xi[:, self._in.have] = x[:, self._in.cols]  # absent inputs read 0
        return xi

    def _map(self, u: np.ndarray, moved: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """(S, K) filtered inputs u and raw ones xi -> (S, M) outputs; rows not started
        yet stay NaN."""
        a = self.weights.arrays
        lin = u @ a["a"].T + a["c"]
        rest = (u - self._r) if self.rest else None
        if rest is not None:
            lin = lin + rest @ a["b"].T
        if self._lvl is not None:  # a face's own rest reading (``set_rest_reading``)
            lin = lin + np.maximum(self._r - self._ceil, 0.0) @ self._lvl[:, : self._m_cols]
        if len(self._do):  # the detail, on each output's own input
            lin[:, self._do] += self._d[self._do] * (xi[:, self._di] - u[:, self._di])
        if self._hidden:
            rest = np.zeros_like(u) if rest is None else rest
            z = (np.concatenate([u, rest], axis=1) - a["mu"]) / a["sd"]
            lin = lin + np.tanh(z @ a["w1"].T + a["b1"]) @ a["w2"].T + a["b2"]
        m = np.clip(lin, 0.0, 1.0)
        if len(self._lo):  # the lift
            j, lo = self._li, self._lo
            rise = a["lift_gain"][lo] * (self._lp - self._r[:, j] - a["lift_knee"][lo])
            if self._lift_top:  # the top kept through a restart: the same face came back
                top = np.fmax(self._top, rise)
                self._top = top if moved.all() else np.where(moved[:, None], top, self._top)
                rise = rise / np.maximum(self._top, 1.0)
            m[:, lo] = np.fmax(m[:, lo], np.clip(rise, 0.0, 1.0))
        return m

    # -- whole takes (issue 38) ---------------------------------------------------------------

    def clean(self, anim: Animation) -> Animation:
        """Reset, then step every valid frame; runs of usual frames compiled where a long
        take turns the compiled loops on (learned/map_take.py)."""
        from faceclean.learned import map_take

        return map_take.clean(self, anim)

    clean._finite_checked = True  # type: ignore[attr-defined]
    clean.reset_then_step = True  # type: ignore[attr-defined] # filters/base.py ``stepwise``
