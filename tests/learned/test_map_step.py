"""The tracker map's step as issue 38 made it cheaper gives the previous step's bits.

``Previous`` is the step as it was: the take's columns gathered into the model's inputs
and scattered back by index, the detail a product with a diagonal matrix, a new array for
every elementwise result. The step now reads and writes an ARKit take's run of columns as
a view, adds the detail elementwise and computes in place: the same operations on the same
operands, so the same bits, for one stream and for many, for a whole take's compiled run
too, through lost values, a repeated time and a restart. (The shipped kind's whole take
now goes in one compiled pass, learned/map_take.py, its sums in another order: within
1e-12 of the previous run, not its bits.)
"""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.filters.base import MAX_ABS, MIN_DT
from faceclean.filters.one_euro import DT_MIN
from faceclean.learned.map_weights import MapWeights
from faceclean.learned.tracker_map import TrackerMap
from faceclean.settings import MODELS


class Previous(TrackerMap):
    """``_usual`` and ``_run`` as they were before issue 38's second round (but the blink
    lift, which reads its own low-pass of the raw input since, added as the step adds it)."""

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        k, m = len(self.weights.inputs), self._m_cols
        dx = np.zeros((k, m + len(self._lo)))
        dx[self._di, self._do] = self._d[self._do]
        self._dx = dx if len(self._do) else None

    def _usual(self, x, tt):
        if not self.prefilter or self._hidden or not np.abs(x).max() <= MAX_ABS:
            return None
        dt = tt - self._t
        lo, hi = (dt[0], dt[0]) if len(dt) == 1 else (dt.min(), dt.max())
        if not (lo > MIN_DT and hi <= self.pre.max_gap):
            return None
        xi = x if self._in.identity else self._in_matrix(x)
        h = np.maximum(dt, DT_MIN)[:, None] if lo != hi else max(float(lo), DT_MIN)
        u, edx = self._u, self._edx
        e = xi - u
        edx += (h / (h + self._tau_d)) * (e / h - edx)
        g = h * (self._mc2pi + self._beta2pi * np.abs(edx))
        u += (g / (1.0 + g)) * e
        if len(self._lo):
            self._lp += h / (h + self._lift_tau) * (xi[:, self._li] - self._lp)
        np.minimum(self._r, u, out=self._r)
        y = u @ self._ab
        y += self._r @ self._nb
        if self._dx is not None:
            y += xi @ self._dx
        y += self._c
        if len(self._lo):
            y[:, self._m_cols :] += self._lp * self._lg
        if self._lift_top:
            lift = y[:, self._m_cols :]
            np.maximum(self._top, lift, out=self._top)
            lift /= np.maximum(self._top, 1.0)
        np.clip(y, 0.0, 1.0, out=y)
        if len(self._lo):
            m = self._m_cols
            lifted = np.maximum(y[:, self._lo], y[:, m:])
            y = y[:, :m].copy()
            y[:, self._lo] = lifted
        if self._band is not None:
            d = y - self._m
            np.clip(d, -self._band, self._band, out=d)
            y -= d
        self._m = y
        if self._direct:
            out = y
        else:
            out = x.copy()
            out[:, self._out.cols] = y[:, self._out.have]
        self._t = tt.copy()
        self._y = out
        return out

    def clean(self, anim):
        from faceclean.learned import map_take

        return map_take.clean(self, anim, run_of=self._run)

    def _run(self, xs, ts, dt):
        from faceclean.filters import compiled

        xi = xs if self._in.identity else self._in_matrix(xs)
        h = np.empty(len(xs))
        h[0] = dt
        h[1:] = np.diff(ts)
        np.maximum(h, DT_MIN, out=h)
        u, edx, r = self._u[0].copy(), self._edx[0].copy(), self._r[0].copy()
        consts = [np.array(c, np.float64) for c in (self._tau_d, self._mc2pi, self._beta2pi)]
        v = r.copy()  # the smoothed rest's state, unused (rest_tau 0)
        U, R = compiled.map_prefilter(u, edx, r, v, np.ascontiguousarray(xi), h, *consts)
        pairs = [(U, self._ab), (R, self._nb)] + ([(xi, self._dx)] if self._dx is not None else [])
        y = compiled.affine(self._c, *pairs)
        m = self._m_cols
        lp = self._lp[0].copy()
        for n in range(len(y) if len(self._lo) else 0):
            lp += h[n] / (h[n] + self._lift_tau) * (xi[n, self._li] - lp)
            y[n, m:] += lp * self._lg
        if self._lift_top:
            lift = y[:, m:]
            top = np.maximum.accumulate(np.concatenate([self._top, lift]), axis=0)[1:]
            lift /= np.maximum(top, 1.0)
            self._top = top[-1:].copy()
        np.clip(y, 0.0, 1.0, out=y)
        if len(self._lo):
            lifted = np.maximum(y[:, self._lo], y[:, m:])
            y = y[:, :m].copy()
            y[:, self._lo] = lifted
        if self._band is not None:
            held = compiled.deadband(np.concatenate([self._m, y]), self._band)
            if held is None:
                for n in range(len(y)):
                    prev = self._m[0] if n == 0 else y[n - 1]
                    y[n] -= np.clip(y[n] - prev, -self._band, self._band)
            else:
                y = held[1:]
        if self._direct:
            outv = y
        else:
            outv = xs.copy()
            outv[:, self._out.cols] = y[:, self._out.have]
        self._u, self._edx, self._r, self._lp = u[None], edx[None], r[None], lp[None]
        self._m, self._t, self._y = y[-1:].copy(), ts[-1:].copy(), outv[-1:].copy()
        return outv


def _weights(which: str) -> MapWeights:
    """The shipped map; with a per-output deadband and no lift; or with a lift (some
    knees at 0, its top kept), a scalar deadband and a detail on some outputs only. The
    band is never widened by the noise and the rest is the plain minimum: the frozen step
    predates both (learned/band.py, the rest's ``rest_tau``, ``rest_warm`` and
    ``rest_drift``; their paths are checked against each other in
    tests/learned/test_tracker_map.py)."""
    w = MapWeights.load(MODELS / "mediapipe.npz")
    w = MapWeights.build(dict(w.config, noise_band=0.0, rest_tau=0.0, rest_warm=0.0,
                              rest_drift=0.0), w.arrays)  # fmt: skip
    m = len(w.outputs)
    if which == "shipped":  # its own lift (blinks) included
        return w
    if which == "per-output band":
        band = np.linspace(0.0, 0.08, m)
        band[::7] = 0.0
        arrays = dict(w.arrays, lift_gain=np.zeros(m))
        return MapWeights.build(dict(w.config, deadband=band.tolist()), arrays)
    own = [j for j, name in enumerate(w.outputs) if name in w.inputs]
    gain, knee, detail = np.zeros(m), np.full(m, 0.1), np.array(w.arrays["detail"])
    gain[own[:6]] = 4.0
    knee[own[:3]] = 0.0
    detail[::3] = 0.0
    arrays = dict(w.arrays, lift_gain=gain, lift_knee=knee, detail=detail)
    return MapWeights.build(dict(w.config, lift_top=True, deadband=0.02), arrays)


def _take(n: int, s: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, s, 52) frames with rests at 0 and closures, (n, s) uneven times, lost values,
    a repeated time and a gap (a restart)."""
    rng = np.random.default_rng(seed)
    x = np.clip(0.2 + np.cumsum(rng.normal(0, 0.04, (n, s, 52)), axis=0), 0, 1)
    x[n // 4 : n // 4 + 8, :, :10] = np.array([0.3, 0.6, 0.9, 1, 1, 0.8, 0.4, 0.1])[:, None, None]
    t = np.cumsum(rng.uniform(0.5, 1.5, (n, s)) / 60.0, axis=0)
    x[30, 0, 5] = np.nan  # a lost value
    x[31, -1] = np.nan  # a lost frame
    x[40, 0, 2] = np.inf
    t[50, -1] = t[49, -1]  # a repeated time: held
    t[70:, 0] += 2.0  # a gap: a restart
    return x, t


def _same(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_array_equal(np.asarray(a).view(np.uint64), np.asarray(b).view(np.uint64))


@pytest.mark.parametrize("which", ["shipped", "per-output band", "lift"])
@pytest.mark.parametrize("names", ["arkit", "reordered"])
@pytest.mark.parametrize("streams", [1, 5])
def test_the_step_gives_the_previous_steps_bits(which, names, streams):
    w = _weights(which)
    cols = ARKIT52 if names == "arkit" else (*ARKIT52[26:], *ARKIT52[:26])
    new, old = TrackerMap(weights=w, names=cols), Previous(weights=w, names=cols)
    assert (new._xs is not None) == (names == "arkit")  # the view, or the gather
    x, t = _take(160, streams, 3)
    x = x[:, :, [ARKIT52.index(c) for c in cols]]
    usual, taken = new._usual, []
    new._usual = lambda x, tt: taken.append(usual(x, tt)) or taken[-1]
    for n in range(len(x)):
        xa, ta = (x[n, 0], float(t[n, 0])) if streams == 1 else (x[n], t[n])
        _same(new.step(xa, ta), old.step(xa, ta))
        for key in ("_u", "_edx", "_r", "_m", "_y", "_t", "_top", "_lp"):
            _same(getattr(new, key), getattr(old, key))
    done = sum(out is not None for out in taken)
    assert len(x) * 0.8 < done < len(x)  # the usual frame, and the general path, both ran


@pytest.mark.parametrize("which", ["shipped", "per-output band", "lift"])
@pytest.mark.parametrize("names", ["arkit", "reordered"])
def test_a_whole_takes_compiled_run_gives_the_previous_runs_numbers(which, names, monkeypatch):
    from faceclean.filters import compiled
    from faceclean.learned import map_take

    was = compiled.enabled()
    if not compiled.enable(warm=False):
        pytest.skip("numba not installed: a whole take steps in numpy")
    w = _weights(which)
    cols = ARKIT52 if names == "arkit" else (*ARKIT52[26:], *ARKIT52[:26])
    x, t = _take(400, 1, 8)
    anim = Animation(t[:, 0], x[:, 0][:, [ARKIT52.index(c) for c in cols]], cols)
    new, old = TrackerMap(weights=w, names=cols), Previous(weights=w, names=cols)
    runs, run = [], map_take.run
    monkeypatch.setattr(map_take, "run", lambda tm, *a: runs.append(len(a[0])) or run(tm, *a))
    try:
        got, want = new.clean(anim).values, old.clean(anim).values
        # one pass (compiled.map_run), the blink lift in it: the same sums in another order
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        assert np.nanmax(np.abs(got - want)) > 0  # (it is the other order that ran)
    finally:
        if not was:
            compiled.disable()
    assert sum(runs) > 300  # most frames went through the compiled run
