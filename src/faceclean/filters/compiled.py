"""Compiled runs of usual frames, for a process that cleans the same take again and again.

``StreamCleaner.clean`` sends a usual frame (filters/base.py: every value good, more than
MIN_DT and at most max_gap after the last one) to the cleaner's ``_advance``: some 30 us
a frame of numpy calls for One Euro on 52 channels, 24 ms for the tuning page's 12 s
window at 60 fps. The page cleans a take again on every change (ui/offline.py), so there a
run of usual frames goes to one compiled loop instead. Each loop does the arithmetic of
its ``_advance`` in the same order, with no fast-math, so the numbers are the same bit
for bit (tests/filters/test_compiled.py).

Off until a process asks (``enable()``): loading numba costs ~1.8 s, which a one-off
``faceclean clean`` would pay to save ~30 ms. Without numba it stays off, and every
cleaner runs as before.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

# A run: (state, x (N, M) frames, dt (N,) s) -> (state, y (N, M)), one stream.
Run = Callable[[tuple[np.ndarray, ...], np.ndarray, np.ndarray], tuple]

_kernels: dict[str, Callable] = {}


def enable() -> bool:
    """Load and compile the kernels (cached by numba between processes); False without numba."""
    if _kernels:
        return True
    try:
        from numba import njit
    except ImportError:  # the optional ``fast`` extra
        return False
    # error_model="numpy": a division by zero gives inf as numpy's does, never an exception
    jit = njit(boundscheck=False, nogil=True, cache=True, error_model="numpy")
    found = {"one_euro": jit(_one_euro), "inert": jit(_inert)}
    one, x = np.ones(1), np.zeros((1, 1))  # compile now, not at the first change
    try:
        found["one_euro"](one.copy(), one.copy(), x, one, one, one, one, x.copy())
        found["inert"](one.copy(), one.copy(), x, one, one, one, one, one, one, x.copy())
    except Exception:  # noqa: BLE001 - e.g. no writable cache folder: numpy steps as before
        return False
    _kernels.update(found)
    return True


def enabled() -> bool:
    return bool(_kernels)


def disable() -> None:
    _kernels.clear()


def _per_channel(m: int, values) -> list[np.ndarray]:
    return [np.broadcast_to(np.asarray(v, np.float64), (m,)).copy() for v in values]


def one_euro(m: int, min_cutoff, beta, d_cutoff) -> Run | None:
    """One Euro's run (filters/one_euro.py) for M channels' settings (scalars or (M,)), or
    None when off."""
    kernel = _kernels.get("one_euro")
    if kernel is None:
        return None
    mc, beta, dc = _per_channel(m, (min_cutoff, beta, d_cutoff))

    def run(state, x, dt):
        y, edx = state[0][0].copy(), state[1][0].copy()  # (M,) each, one stream
        out = np.empty_like(x)
        kernel(y, edx, x, dt, mc, beta, dc, out)
        return (y[None], edx[None]), out

    return run


def inert(m: int, min_cutoff, beta, w_d, ea, k) -> Run | None:
    """The inert adaptive default's run (learned/adaptive.py ``_advance_inert``, without a
    transient gain) for M channels' constants, or None when off."""
    kernel = _kernels.get("inert")
    if kernel is None:
        return None
    mc, beta, w_d, ea, k = _per_channel(m, (min_cutoff, beta, w_d, ea, k))

    def run(state, x, dt):
        y, edx = state[0][0].copy(), state[1][0].copy()
        out = np.empty_like(x)
        kernel(y, edx, x, dt, mc, beta, w_d, ea, k, out)
        return (y[None], edx[None]), out

    return run


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
