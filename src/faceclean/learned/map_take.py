"""The tracker map over a whole take: runs of usual frames compiled (issue 38).

``TrackerMap.clean`` is reset-then-step (``Stepper.clean``) until a take is long enough to
turn the compiled loops on (filters/compiled.py ``for_take``). Then a run of usual frames
(learned/tracker_map.py ``_usual``'s: every value within MAX_ABS, each frame more than
MIN_DT and at most max_gap after the last) goes through at once, the state ending as
stepping leaves it. Equal to stepping within 1e-12 (the contract's ``whole_take`` clause,
tests/test_contract.py): the same arithmetic, its sums in another order.

Where the map is the shipped kind (no hidden layer, A u only on each output's own input)
one compiled pass does each frame whole, the pre-filter, the rises' product, the detail,
the clip, the blink lift and the band, with no (N, K) array between them
(``compiled.map_run``):

    m = clip(c + (u - r) B' + a u[own] + d x[own], 0, 1)     a = A_jj - d_j
    m_j = max(m_j, clip(l_j / max(1, T_j), 0, 1))            the lift, l_j = g_j (p - r)_j - g_j k_j

Otherwise the pre-filter and the products are compiled apart and the rest done in numpy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from faceclean.filters import base, compiled
from faceclean.filters.base import BLOCK, MIN_DT, Stepper
from faceclean.filters.one_euro import DT_MIN
from faceclean.learned import band as noise

# Rows per product: OpenBLAS runs a product of fewer than 65,536 x 4 multiply-adds in the
# calling thread (96 x 51 x 51 = 249,696): its threads, on a busy machine, made the
# hour's products 5x slower (docs/BENCHMARKS.md).
ROWS = 96
CHUNK = 1024  # frames a pass: its (C, K) arrays stay in cache, and small beside the take

# The tracker map being cleaned (learned/tracker_map.py's TrackerMap, which calls in here:
# its state and constants are read and written as its own step leaves them).
Map = Stepper

if TYPE_CHECKING:
    from faceclean.animation import Animation


def clean(tm: Map, anim: Animation, run_of=None) -> Animation:
    """Reset, then step every valid frame of ``anim``, runs of usual frames at once (by
    ``run``, or ``run_of(xs, ts, dt)``)."""
    go = run_of or (lambda *a: run(tm, *a))
    idx = np.flatnonzero(anim.valid)
    if (
        not tm.prefilter
        or tm._hidden
        or tm._lvl is not None  # a face's own rest reading: stepped (tracker_map.py)
        or anim.n_channels != len(tm.names)
        or not compiled.for_take(len(idx))
    ):
        return Stepper.clean(tm, anim)
    tm.reset()
    out = np.empty_like(anim.values)  # (N, M); every row written below, or NaN
    gone = np.ones(len(out), bool)
    gone[idx] = False
    out[gone] = np.nan
    t64 = anim.times[idx].astype(np.float64)  # (V,) s
    lost = kept = 0
    for a in range(0, len(idx), BLOCK):
        rows, t = idx[a : a + BLOCK], t64[a : a + BLOCK]
        whole = rows[-1] - rows[0] == len(rows) - 1  # no missing row: views, no gather
        span = slice(rows[0], rows[-1] + 1)
        x = anim.values[span] if whole else anim.values[rows]  # (B, M), read only
        x = np.asarray(x, np.float64)
        sane = base.sane_cells(x)  # (B, M) bool
        ok = sane.all(axis=1)
        d = np.diff(t)
        chain = np.concatenate([[False], ok[1:] & (d > MIN_DT) & (d <= tm.pre.max_gap)])
        breaks = np.append(np.flatnonzero(~chain), len(x))  # runs end before these
        k = 0
        while k < len(x):
            if ok[k] and tm._y is not None and tm._y.shape == (1, x.shape[1]):
                dt = t[k] - float(tm._t[0])
                warm = tm._rest_warm is not None and not t[k] - tm._t0[0] > tm._rest_warm_max
                if MIN_DT < dt <= tm.pre.max_gap and not warm:  # _usual's (NaN fails)
                    end = int(breaks[np.searchsorted(breaks, k, side="right")])
                    if whole and run_of is None:  # written in place
                        run(tm, x[k:end], t[k:end], dt, out[span][k:end])
                    else:
                        out[rows[k:end]] = go(x[k:end], t[k:end], dt)
                    k = end
                    continue
            out[rows[k]] = tm.step(x[k], t[k])
            k += 1
        n_lost, n_sane = base.finite_counts(sane, out[span] if whole else out[rows])  # in cache
        lost, kept = lost + n_lost, kept + n_sane
    base.refuse_lost(lost, kept, tm.name)  # (filters/base.py ``check_finite``, block by block)
    return anim.with_values(out)


def run(tm: Map, xs: np.ndarray, ts: np.ndarray, dt: float,
        dest: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """``_usual`` over frames xs (N, M) at ts (N,) s, one stream, the first dt s after the
    last accepted frame: (N, M) outputs, into ``dest`` where given; the state ends as
    stepping leaves it."""
    xi = xs[:, tm._xs] if tm._xs is not None else tm._in_matrix(xs)  # (N, K)
    xi = np.ascontiguousarray(xi)
    h = np.empty(len(xs))  # (N,) s
    h[0] = dt
    h[1:] = np.diff(ts)
    np.maximum(h, DT_MIN, out=h)
    u, edx, r, v = (a[0].copy() for a in (tm._u, tm._edx, tm._r, tm._v))  # (K,)
    lp = tm._lp[0].copy()  # (L,) the lift's low-pass
    consts = [np.array(c, np.float64) for c in (tm._tau_d, tm._mc2pi, tm._beta2pi)]
    consts.append(tm._rest_rate)  # (K,) 1/s, the rest's smoothing (inf: none)
    consts.append(tm._rest_drift)  # (K,) weight/s, the rest's climb (0: none)
    y = _one_pass(tm, (u, edx, r, v), lp, xi, h, consts)
    if y is None:
        y = _apart(tm, (u, edx, r, v), lp, xi, h, consts)
    outv = np.empty_like(xs) if dest is None else dest
    if tm._direct:
        outv[:] = y
    elif tm._ys is not None:  # a run of output columns: the others pass through
        outv[:, : tm._ys.start] = xs[:, : tm._ys.start]
        outv[:, tm._ys] = y
        outv[:, tm._ys.stop :] = xs[:, tm._ys.stop :]
    else:
        outv[:] = xs
        outv[:, tm._out.cols] = y[:, tm._out.have]
    tm._u, tm._edx, tm._r, tm._v, tm._lp = u[None], edx[None], r[None], v[None], lp[None]
    tm._m, tm._t, tm._y = y[-1:].copy(), ts[-1:].copy(), outv[-1:].copy()
    return outv


def _shipped_kind(tm: Map) -> tuple | None:
    """(W (K, M), c (M,)), (a, ai, d, di) (M,) and the lift's (lo, li, g, g k) (L,) for
    ``compiled.map_run``, or None where the map is not the shipped kind (A beyond each
    output's own input)."""
    w = tm.weights
    m = len(w.outputs)
    own = (tm._ab + tm._nb)[:, :m]  # (K, M): A' - D, what multiplies u itself
    ai = np.array([w.inputs.index(o) if o in w.inputs else 0 for o in w.outputs], np.intp)
    a = own[ai, np.arange(m)].copy()  # (M,)
    rest = own.copy()
    rest[ai, np.arange(m)] = 0.0
    if rest.any():
        return None
    d = np.zeros(m)
    d[tm._do] = tm._dd
    di = ai.copy()
    di[tm._do] = tm._di
    g = w.arrays["lift_gain"][tm._lo].astype(np.float64)
    lift = (tm._lo.astype(np.intp), tm._li.astype(np.intp), g, g * w.arrays["lift_knee"][tm._lo])
    return (np.ascontiguousarray(-tm._nb[:, :m]), tm._c[:m].copy()), (a, ai, d, di), lift


def _one_pass(tm: Map, pre: tuple, lp: np.ndarray, xi: np.ndarray, h: np.ndarray,
              consts: list):  # fmt: skip
    """The shipped kind: the pre-filter compiled, the rises' product by BLAS, the rest
    (the own terms, the clip, the band) one compiled pass: (N, M), or None (another kind,
    or off). Its arrays are kept from run to run (no fresh pages per block)."""
    if not hasattr(tm, "_kind"):
        tm._kind = _shipped_kind(tm)
    if tm._kind is None or not compiled.have("map_prefilter", "map_run"):
        return None
    (w, c), own, (lo, li, g, gk) = tm._kind
    n, k, m = len(xi), xi.shape[1], len(c)
    if getattr(tm, "_room", None) is None or len(tm._room[2]) < n:
        tm._room = [np.empty((CHUNK, k)), np.empty((CHUNK, k)), np.empty((max(n, BLOCK), m))]
    band = (0, np.zeros(m), 0.0, noise.TAU, noise.CAP)
    if tm._noise_c > 0:
        band = (2, tm._band, tm._noise_c, noise.TAU, noise.CAP)
    elif tm._band is not None:
        band = (1, tm._band, 0.0, noise.TAU, noise.CAP)
    st = tm._noise
    state = st.p1[0].copy(), st.p2[0].copy(), st.s[0].copy()  # (M,)
    top = tm._top[0].copy() if tm._lift_top else np.ones(len(lo))  # (L,) the lift's top
    lift = (lo, li, g, gk, tm._lift_top, top, lp, tm._lift_tau)  # lp (L,) in place
    p, y0 = tm._room[2][:n], tm._m[0]  # the outputs (N, M); the one before
    for a in range(0, n, CHUNK):  # the state carries from chunk to chunk, in place
        x, dt, q = xi[a : a + CHUNK], h[a : a + CHUNK], p[a : a + CHUNK]
        U, Z = (b[: len(x)] for b in tm._room[:2])  # u, u - r (C, K)
        compiled.map_prefilter(*pre, x, dt, *consts, rises=True, out=(U, Z))
        for b in range(0, len(x), ROWS):  # (u - r) B', in one thread (ROWS)
            np.matmul(Z[b : b + ROWS], w, out=q[b : b + ROWS])
        compiled.map_run(q, U, Z, x, dt, c, own, lift, band, y0, state)
        y0 = q[-1]
    st.p1, st.p2, st.s = (v[None] for v in state)
    if tm._lift_top:
        tm._top = top[None]
    return p


def _apart(tm: Map, pre: tuple, lp: np.ndarray, xi: np.ndarray, h: np.ndarray,
           consts: list):  # fmt: skip
    """The pre-filter and the products compiled apart, the rest in numpy: (N, M)."""
    U, R = compiled.map_prefilter(*pre, xi, h, *consts)
    # y = u (A + B)' - r B' + d x + c, (N, M+L), as ``_usual``; the detail's -d u in _ab
    y = compiled.affine(tm._c, (U, tm._ab), (R, tm._nb))
    if len(tm._do):  # + d x: the one term of each output's own input
        y[:, tm._do] += xi[:, tm._di] * tm._dd
    m = tm._m_cols
    if len(tm._lo):  # + g p, p += h / (h + tau) (x - p) the lift's low-pass, in place
        a, x = h / (h + tm._lift_tau), xi[:, tm._li]
        for n in range(len(y)):
            lp += a[n] * (x[n] - lp)
            y[n, m:] += lp * tm._lg
    if tm._lift_top:  # l / max(1, the largest l so far)
        lift = y[:, m:]
        top = np.maximum.accumulate(np.concatenate([tm._top, lift]), axis=0)[1:]
        lift /= np.maximum(top, 1.0)
        tm._top = top[-1:].copy()
    np.clip(y, 0.0, 1.0, out=y)
    if len(tm._lo):  # the lift: m_j = max(m_j, its lift column)
        lifted = np.maximum(y[:, tm._lo], y[:, m:])
        y = y[:, :m].copy()
        y[:, tm._lo] = lifted
    if tm._noise_c > 0:  # the band widened by the noise (learned/band.py)
        y = noise.run(y, h, tm._m[0], tm._noise, tm._band, tm._noise_c)
    elif tm._band is not None:  # the deadband, from the last output on
        held = compiled.deadband(np.concatenate([tm._m, y]), tm._band)
        if held is None:
            for n in range(len(y)):
                prev = tm._m[0] if n == 0 else y[n - 1]
                y[n] -= np.clip(y[n] - prev, -tm._band, tm._band)
        else:
            y = held[1:]
    return y
