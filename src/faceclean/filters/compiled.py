"""Compiled runs of usual frames, for a process that cleans the same take again and again.

``StreamCleaner.clean`` sends a usual frame (filters/base.py: every value good, more than
MIN_DT and at most max_gap after the last one) to the cleaner's ``_advance``: some 30 us
a frame of numpy calls for One Euro on 52 channels, 24 ms for the tuning page's 12 s
window at 60 fps. The page cleans a take again on every change (ui/offline.py), so there a
run of usual frames goes to one compiled loop instead (One Euro, EMA, Kalman and the
inert shipped default). Each loop does the arithmetic of its ``_advance`` in the same
order, with no fast-math, and takes what needs a numpy function (EMA's expm1, Kalman's
powers of dt) from numpy, so the numbers are the same bit for bit
(tests/filters/test_compiled.py).

Off until a process asks (``enable()``), or a take is long enough to pay for it
(``for_take``: from WHOLE_TAKE_FRAMES frames, where ``clean`` loads numba and only the
kernel it runs, each cached on disk by numba, so no process compiles twice): loading
numba costs ~0.4 s, which a one-off ``faceclean clean`` of a short take would pay to save
~30 ms. Without numba, or with FACECLEAN_NUMBA=0, it stays off and every cleaner steps
in numpy as before, slower (``status()`` says which, for ``info`` and ``bench``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable

import numpy as np

# A run: (state, x (N, M) frames, dt (N,) s, out (N, M)) -> state; one stream, its
# outputs written to out (a view of the take's output: no copy of a block).
Run = Callable[[tuple[np.ndarray, ...], np.ndarray, np.ndarray, np.ndarray], tuple]

# From this many frames a clean loads numba for its whole take: numba's import and one
# cached kernel (~0.45 s) against numpy's ~15 us a frame (docs/BENCHMARKS.md, issue 38).
WHOLE_TAKE_FRAMES = 30_000
OFF = "FACECLEAN_NUMBA"  # set to 0: never load numba (the numpy path, as without it)

_kernels: dict[str, Callable] = {}
_jit: Callable | None = None  # numba's njit with our options, once numba is loaded


def _warm_args() -> dict[str, tuple]:
    """Per kernel: arguments of a one-frame call that compiles (or loads) it."""
    one, x, i = np.ones(1), np.zeros((1, 1)), np.zeros(1, np.intp)
    return {
        "one_euro": (one.copy(), one.copy(), x, one, one, one, one, x.copy()),
        "inert": (one.copy(), one.copy(), x, one, one, one, one, one, one, x.copy()),
        "ema": (one.copy(), x, x + 0.5, np.zeros(1, np.intp), x.copy()),
        "deadband": (x, one, x.copy()),
        "kalman": (*(one.copy() for _ in range(5)), x, one, one, one, one, one, x.copy()),
        "map_prefilter": (one.copy(), one.copy(), one.copy(), one.copy(), x, one, one, one,
                          one, one * np.inf, one * 0.0, 0, x.copy(), x.copy()),
        "affine": (x, x, x.copy()),
        "noise_band": (x, one, one, one.copy(), one.copy(), one.copy(), one, 0.0, 1.0, 0.1,
                       x.copy()),
        "map_run": (x.copy(), x, x, x, one, one, one, i, one, i, i, i, one, one, 1,
                    one.copy(), one.copy(), 0.04, 2, one, 0.0, 1.0, 0.1, one, one.copy(),
                    one.copy(), one.copy()),
    }  # fmt: skip


def enable(warm: bool = True) -> bool:
    """Load numba (False without it, or with FACECLEAN_NUMBA=0); ``warm``: compile every
    kernel now (cached by numba between processes), not at its first run."""
    global _jit
    if _jit is None:
        if os.environ.get(OFF, "").strip() == "0":
            return False
        try:
            from numba import njit
        except ImportError:  # the optional ``fast`` extra
            return False
        # error_model="numpy": a division by zero gives inf as numpy's does, never an exception
        _jit = njit(boundscheck=False, nogil=True, cache=True, error_model="numpy")
        globals().update({name: _jit(f) for name, f in _HELPERS.items()})
    if warm:
        return all(_kernel(name) is not None for name in _SOURCES)
    return True


def for_take(frames: int) -> bool:
    """Whether a clean of ``frames`` frames runs compiled: on already, or long enough
    (WHOLE_TAKE_FRAMES) to pay for loading numba, which it then loads."""
    if _jit is not None:
        return True
    return frames >= WHOLE_TAKE_FRAMES and enable(warm=False)


def enabled() -> bool:
    return _jit is not None


def have(*names: str) -> bool:
    """Whether every kernel ``names`` is on (compiled, or loaded from numba's cache)."""
    return all(_kernel(name) is not None for name in names)


def disable() -> None:
    global _jit
    _jit = None
    _kernels.clear()
    globals().update(_HELPERS)


def status(frames: int | None = None) -> str:
    """One line for ``info`` and ``bench``: how a long take (or one of ``frames`` frames)
    is cleaned here."""
    try:
        from importlib.metadata import version

        have = version("numba")
    except Exception:  # noqa: BLE001 - not installed (PackageNotFoundError), or broken
        have = None
    if os.environ.get(OFF, "").strip() == "0":
        return f"numpy (slower: {OFF}=0 keeps numba off)"
    if have is None:
        return "numpy (slower: numba not installed; pip install 'faceclean[fast]')"
    if frames is not None and frames < WHOLE_TAKE_FRAMES:
        return f"numpy steps (compiled from {WHOLE_TAKE_FRAMES} frames: numba {have})"
    return f"compiled from {WHOLE_TAKE_FRAMES} frames (numba {have}, kernels cached)"


def _kernel(name: str) -> Callable | None:
    """The compiled kernel ``name``, compiled (or loaded from numba's cache) at its first
    use; None while off, or where it cannot compile (e.g. no writable cache folder)."""
    k = _kernels.get(name)
    if k is None and _jit is not None:
        try:
            k = _jit(_SOURCES[name])
            k(*_warm_args()[name])
        except Exception:  # noqa: BLE001 - numpy steps as before
            return None
        _kernels[name] = k
    return k


def _per_channel(m: int, values) -> list[np.ndarray]:
    return [np.broadcast_to(np.asarray(v, np.float64), (m,)).copy() for v in values]


def _run(kernel: Callable, *consts: np.ndarray) -> Run:
    """A run of ``kernel(*state rows, x, dt, *consts, out)``, one stream, on a copy of the
    state (the rows are updated in place)."""

    def run(state, x, dt, out):
        rows = [s[0].copy() for s in state]  # (M,) each
        kernel(*rows, x, dt, *consts, out)
        return tuple(r[None] for r in rows)

    return run


def one_euro(m: int, min_cutoff, beta, d_cutoff) -> Run | None:
    """One Euro's run (filters/one_euro.py) for M channels' settings (scalars or (M,)), or
    None when off."""
    kernel = _kernel("one_euro")
    return None if kernel is None else _run(kernel, *_per_channel(m, (min_cutoff, beta, d_cutoff)))


def inert(m: int, min_cutoff, beta, w_d, ea, k) -> Run | None:
    """The inert adaptive default's run (learned/adaptive.py ``_advance_inert``, without a
    transient gain) for M channels' constants, or None when off."""
    kernel = _kernel("inert")
    return (
        None if kernel is None else _run(kernel, *_per_channel(m, (min_cutoff, beta, w_d, ea, k)))
    )


def ema(m: int, gamma, tau) -> Run | None:
    """Exponential smoothing's run (filters/ema.py): per-frame ``gamma``, or ``tau`` s
    (M channels' settings, the other None), or None when off. The gains are computed by
    numpy, as ``_advance`` computes them, for every frame of the run at once, once per
    distinct ``tau`` (a tuned preset has a few: 5 of 52 channels' expm1 per frame)."""
    kernel = _kernel("ema")
    if kernel is None:
        return None
    if gamma is not None:
        gains, col = _per_channel(m, (gamma,))[0][None], np.arange(m)  # (1, M): every frame
    else:
        taus, col = np.unique(_per_channel(m, (tau,))[0], return_inverse=True)  # (U,), (M,)

    def run(state, x, dt, out):
        if gamma is None:
            with np.errstate(over="ignore"):
                g = -np.expm1(-dt[:, None] / taus)  # (N, U)
        else:
            g = gains
        return _run(kernel, col)(state, x, g, out)  # the gains in dt's place

    return run


def kalman(m: int, q, r) -> Run | None:
    """The Kalman filter's run (filters/kalman.py) for M channels' ``q`` and ``r``, or
    None when off; dt's powers computed by numpy as ``_advance`` computes them."""
    kernel = _kernel("kalman")
    if kernel is None:
        return None
    q, r2 = _per_channel(m, (q, np.asarray(r, np.float64) ** 2))

    def run(state, x, dt, out):
        return _run(kernel, dt**3, dt**2, q, r2)(state, x, dt, out)  # state: p, v, a, b, c

    return run


def deadband(m: np.ndarray, band: np.ndarray) -> np.ndarray | None:
    """y[n] = m[n] - clip(m[n] - y[n-1], -band, band), y[0] = m[0], over (N, M) outputs m
    (a tracker map's deadband, learned/tracker_map.py, as its fit scores it); None when off."""
    kernel = _kernel("deadband")
    if kernel is None:
        return None
    m = np.ascontiguousarray(m, dtype=np.float64)
    y = np.empty_like(m)
    if len(m):  # (the kernel writes the first frame)
        kernel(m, np.ascontiguousarray(band, np.float64), y)
    return y


def _deadband(m, band, y):
    """Into y (N, M): the first frame of m, then each frame what is left of m after its
    change from the last output, clipped to +-band (M,), is taken off."""
    for j in range(m.shape[1]):
        y[0, j] = m[0, j]
    for n in range(1, m.shape[0]):
        for j in range(m.shape[1]):
            d = m[n, j] - y[n - 1, j]
            d = min(max(d, -band[j]), band[j])  # np.clip's order: maximum, then minimum
            y[n, j] = m[n, j] - d


def _ema(y, x, gains, col, out):
    """In place: y (M,) the state; x (N, M); gains (N, U), or (1, U) for every frame, one
    per distinct setting, col (M,) each channel's: alpha = gains[n, col[m]]; out (N, M)
    gets y after each frame."""
    per_frame = 1 if gains.shape[0] > 1 else 0
    for n in range(x.shape[0]):
        g = gains[n * per_frame]
        for m in range(x.shape[1]):
            y[m] = y[m] + g[col[m]] * (x[n, m] - y[m])
            out[n, m] = y[m]


def _kalman(p, v, a, b, c, x, dt, h3, h2, q, r2, out):
    """In place: p, v and P = [[a, b], [b, c]] (M,) the state; x (N, M); dt, h3, h2 (N,)
    s, s^3, s^2; q, r2 (M,); out (N, M) gets p. The process noise q dt^3/3, q dt^2/2,
    q dt in ``_advance``'s order: (q dt^k) / k."""
    for n in range(x.shape[0]):
        h = dt[n]
        for m in range(x.shape[1]):
            pm = p[m] + h * v[m]  # predict
            am = a[m] + h * (2.0 * b[m] + h * c[m]) + q[m] * h3[n] / 3.0
            bm = b[m] + h * c[m] + q[m] * h2[n] / 2.0
            cm = c[m] + q[m] * h
            s = am + r2[m]  # update with the measured position
            k0, k1 = am / s, bm / s
            innov = x[n, m] - pm
            p[m] = pm + k0 * innov
            v[m] = v[m] + k1 * innov
            a[m], b[m], c[m] = (1.0 - k0) * am, (1.0 - k0) * bm, cm - k1 * bm
            out[n, m] = p[m]


def _one_euro(y, edx, x, dt, mc, beta, dc, out):
    """In place: y, edx (M,) the state; x (N, M) frames, dt (N,) s; mc, beta, dc (M,);
    out (N, M) gets y after each frame. alpha(f) = 1 / (1 + 1 / (2 pi f dt)), as numpy
    evaluates it: ((2 pi) f) dt."""
    two_pi = 2.0 * np.pi
    for n in range(x.shape[0]):
        h = max(dt[n], 1e-6)  # one_euro.DT_MIN
        for m in range(x.shape[1]):
            e = edx[m] + 1.0 / (1.0 + 1.0 / (two_pi * dc[m] * h)) * ((x[n, m] - y[m]) / h - edx[m])
            cut = mc[m] + beta[m] * abs(e)
            y[m] = y[m] + 1.0 / (1.0 + 1.0 / (two_pi * cut * h)) * (x[n, m] - y[m])
            edx[m] = e
            out[n, m] = y[m]


def _inert(y, edx, x, dt, mc, beta, w_d, ea, k, out):
    """``_advance_inert`` frame after frame, in place as ``_one_euro``: w_d = 2 pi d_cutoff,
    ea the cut-off's factor, k the prediction's share (M,)."""
    two_pi = 2.0 * np.pi
    for n in range(x.shape[0]):
        h = max(dt[n], 1e-6)
        for m in range(x.shape[1]):
            xm = x[n, m]
            e = edx[m] + 1.0 / (1.0 + 1.0 / (w_d[m] * h)) * ((xm - y[m]) / h - edx[m])
            fc = (mc[m] + beta[m] * abs(e)) * ea[m]
            p = y[m] + k[m] * h * e
            v = p + 1.0 / (1.0 + 1.0 / (two_pi * fc * h)) * (xm - p)
            y[m] = min(max(v, min(xm, 0.0)), max(xm, 1.0))
            edx[m] = e
            out[n, m] = y[m]


def map_prefilter(u, edx, r, v, xi: np.ndarray, h: np.ndarray, tau_d, mc2pi, beta2pi,
                  rate_r=None, drift=None, rises: bool = False,
                  out: tuple | None = None):  # fmt: skip
    """A tracker map's pre-filter over a run of usual frames (learned/tracker_map.py
    ``_usual``, one stream): state u, edx, r, v (K,) updated in place; xi (N, K) the
    inputs, h (N,) s the steps; tau_d, mc2pi, beta2pi (K,); rate_r (K,) 1/s the rest's smoothing,
    1 / tau (inf: none, v unused); drift (K,) weight/s the rest's climb (None: 0). Returns
    (U, R) (N, K), into ``out`` where given: the filtered inputs and their rest after each
    frame (``rises``: u - r instead); None when off."""
    kernel = _kernel("map_prefilter")
    if kernel is None:
        return None
    U, R = out if out is not None else (np.empty_like(xi), np.empty_like(xi))
    rate_r = np.full(len(u), np.inf) if rate_r is None else np.asarray(rate_r, np.float64)
    drift = np.zeros(len(u)) if drift is None else np.asarray(drift, np.float64)
    kernel(u, edx, r, v, xi, h, tau_d, mc2pi, beta2pi, rate_r, drift, int(rises), U, R)
    return U, R


def _map_prefilter(u, edx, r, v, xi, h, tau_d, mc2pi, beta2pi, rate_r, drift, rises, U, R):
    """In place: ``_prefilter_frame`` frame after frame, U and R (N, K) getting u and r
    (rises: u - r)."""
    for n in range(xi.shape[0]):
        _prefilter_frame(u, edx, r, v, xi[n], h[n], tau_d, mc2pi, beta2pi, rate_r, drift)
        for j in range(xi.shape[1]):
            U[n, j] = u[j]
            R[n, j] = u[j] - r[j] if rises else r[j]


def _prefilter_frame(u, edx, r, v, x, h, tau_d, mc2pi, beta2pi, rate_r, drift):
    """One frame x (K,) h s later, in place: ``_usual``'s One Euro in its arithmetic
    order, a = h / (h + tau) and 2 pi f h / (1 + 2 pi f h), then the rest
    r = min(r + drift h, u), or where rate_r is finite v += (1 - exp(-h rate_r)) (u - v)
    and r = min(r + drift h, v) (drift 0: r + 0 is r, the same bits as without it)."""
    for j in range(x.shape[0]):
        e = x[j] - u[j]
        edx[j] = edx[j] + (h / (h + tau_d[j])) * (e / h - edx[j])
        g = h * (mc2pi[j] + beta2pi[j] * abs(edx[j]))
        u[j] = u[j] + (g / (1.0 + g)) * e
        if rate_r[j] < math.inf:
            v[j] = v[j] + (u[j] - v[j]) * -math.expm1(-h * rate_r[j])
            r[j] = min(r[j] + drift[j] * h, v[j])
        else:
            r[j] = min(r[j] + drift[j] * h, u[j])


def affine(c: np.ndarray, *pairs: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
    """y = c + sum of a @ w over ``pairs`` of a (N, K) and w (K, P), c (P,): (N, P); each
    product summed over K in order, one row at a time, in one thread (BLAS would start
    threads for a long run, and on a busy machine wait for them); None when off."""
    kernel = _kernel("affine")
    if kernel is None:
        return None
    y = np.empty((len(pairs[0][0]), len(c)))
    y[:] = c
    for a, w in pairs:
        kernel(np.ascontiguousarray(a, np.float64), np.ascontiguousarray(w, np.float64), y)
    return y


def _affine(a, w, y):
    """In place: y (N, P) += a (N, K) @ w (K, P), k ascending, vectorised over P."""
    for n in range(a.shape[0]):
        for k in range(a.shape[1]):
            v = a[n, k]
            for j in range(w.shape[1]):
                y[n, j] += v * w[k, j]


def noise_band(m, h, y0, p1, p2, s, floor, c: float, tau: float, cap: float
               ) -> np.ndarray | None:  # fmt: skip
    """learned/band.py's band over a run of one stream's frames m (N, M), h (N,) s, after
    the output y0 (M,); p1, p2, s (M,) its state, updated in place. (N, M), or None when
    off."""
    kernel = _kernel("noise_band")
    if kernel is None:
        return None
    y = np.empty_like(m)
    kernel(m, h, y0, p1, p2, s, floor, float(c), float(tau), float(cap), y)
    return y


def _noise_band(m, h, y0, p1, p2, s, floor, c, tau, cap, y):
    """In place: y (N, M) the band's outputs, ``_band_frame`` frame after frame."""
    for n in range(m.shape[0]):
        prev = y0 if n == 0 else y[n - 1]
        _band_frame(m[n], prev, p1, p2, s, floor, c, h[n] / (h[n] + tau), cap, y[n])


def _band_frame(m, prev, p1, p2, s, floor, c, a, cap, y):
    """One frame of learned/band.py's band in its ``step`` order, in place: the map's
    values m (M,) after the output prev, a = h / (h + tau); y (M,) may be m itself."""
    for j in range(m.shape[0]):
        mj = m[j]
        d, d0 = mj - p1[j], p1[j] - p2[j]
        v = min(abs(d), abs(d0)) * (d * d0 < 0.0)  # a reversal (no branch: noise turns
        s[j] = s[j] + a * (v - s[j])  # about every other frame, and a branch mispredicts)
        eps = min(cap, max(floor[j], c * s[j]))
        y[j] = mj - min(max(mj - prev[j], -eps), eps)
        p2[j] = p1[j]
        p1[j] = mj


def map_run(p, u, z, xi, h, c, own, lift, band, y0, bstate) -> np.ndarray | None:
    """The end of a tracker map's run of usual frames (learned/map_take.py), in place
    into p (N, M), the map's products (u - r) B' per frame: + c_j + a_j u[ai_j] + d_j
    x[di_j] (c (M,), ``own`` (a, ai, d, di) (M,)), clipped to [0, 1]; the blink lift
    (``lift`` (lo, li, g, gk) (L,), top on or off, top, p (L,) in place, tau s): m_lo =
    max(m_lo, clip(l / max(1, T), 0, 1)), l = g (p - r) - gk, r = u - z at li, p += h /
    (h + tau) (x[li] - p), T the largest l so far (1 when off);
    then the band from y0 (M,) on: ``band`` (mode, floor (M,), c, tau s, cap), mode 0
    none, 1 the deadband, 2 widened by the noise, its state ``bstate`` (p1, p2, s) (M,)
    updated in place. u, z, xi (N, K) the filtered inputs, their rises u - r and the raw
    inputs, h (N,) s. p, or None when off."""
    kernel = _kernel("map_run")
    if kernel is None:
        return None
    mode, floor, nc, tau, cap = band
    lo, li, g, gk, on, top, lp, ltau = lift
    kernel(p, u, z, xi, h, c, *own, lo, li, g, gk, int(on), top, lp, float(ltau), int(mode),
           floor, float(nc), float(tau), float(cap), y0, *bstate)  # fmt: skip
    return p


def _map_run(p, u, z, xi, h, c, a, ai, d, di, lo, li, g, gk, on, top, lp, ltau, mode, floor,
             nc, tau, cap, y0, p1, p2, s):  # fmt: skip
    """In place: p (N, M) the outputs, frame after frame."""
    for n in range(p.shape[0]):
        m, un, x = p[n], u[n], xi[n]
        for j in range(m.shape[0]):
            m[j] = min(max(m[j] + c[j] + a[j] * un[ai[j]] + d[j] * x[di[j]], 0.0), 1.0)
        for q in range(lo.shape[0]):  # the lift, before the band
            k = li[q]
            lp[q] = lp[q] + h[n] / (h[n] + ltau) * (x[k] - lp[q])
            v = g[q] * (lp[q] - (un[k] - z[n, k])) - gk[q]
            if on:
                top[q] = max(top[q], v)
                v = v / max(top[q], 1.0)
            m[lo[q]] = max(m[lo[q]], min(max(v, 0.0), 1.0))
        prev = y0 if n == 0 else p[n - 1]
        if mode == 2:
            _band_frame(m, prev, p1, p2, s, floor, nc, h[n] / (h[n] + tau), cap, m)
        elif mode == 1:
            for j in range(m.shape[0]):
                m[j] = m[j] - min(max(m[j] - prev[j], -floor[j]), floor[j])


_SOURCES = {"one_euro": _one_euro, "inert": _inert, "ema": _ema, "kalman": _kalman,
            "deadband": _deadband, "map_prefilter": _map_prefilter,
            "affine": _affine, "noise_band": _noise_band, "map_run": _map_run}  # fmt: skip
# Per-frame helpers the kernels call: compiled first, in their place (numba resolves a
# kernel's globals as it compiles it).
_HELPERS = {"_prefilter_frame": _prefilter_frame, "_band_frame": _band_frame}
