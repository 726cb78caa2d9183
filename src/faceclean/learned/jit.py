"""Optional numba kernels for the learned runtime's step (used when numba is installed):
the LSTM's step (``step``, ``run``) and, for many streams, its gate arithmetic between
numpy's products and tanh (``lstm_cell``, ``lstm_out``); the GBT baseline's trees
(``trees``); the FC baseline's elementwise passes around its products (``fc_features``,
``fc_blend``).

Why: for one stream the numpy step (28 us on an idle core) spends about as long in ~30
small ufunc calls as in its two matrix-vector products, so one compiled function that
does the products and the gate arithmetic in one pass takes about 0.6x of it
(docs/BENCHMARKS.md). Its cost per stream hardly falls with more streams, while numpy's
BLAS matrix-matrix products do: beyond ``Learned.jit_max_streams`` numpy runs.

The gate nonlinearity uses a rational tanh (Eigen's float approximation: max absolute
error 3.3e-7 against float64 tanh, tested), which vectorises; libm's scalar tanh would
cost more than the products. Without numba, ``available()`` is False and the runtime
uses its numpy kernel only.

Above ``Learned.jit_max_streams`` the numpy kernel runs, its products and tanh numpy's;
``lstm_cell`` and ``lstm_out`` do the gate arithmetic between them (seven numpy passes
over (H, S) arrays) in two, the same float32 operations in the same order (no fastmath):
the same bits as the numpy kernel.

The trees: a numpy step descends every tree one level per pass, some eight calls a level
on (S M, T) index arrays; compiled, a descent is a few loads. Each order's leaves are
added one tree after another from 0, which is what the numpy path's sequential sums
(``cumsum``) give too: the same bits with or without numba.

FC, many streams: its numpy step makes some 30 passes over (S, 52)-(S, 468) arrays, 4 MB
of features at 1024 streams, out of cache; the two kernels make one pass before the
products and one after, with numpy's arithmetic in numpy's order (no fastmath: the same
bits; the products stay numpy's BLAS calls). ``_max``/``_min`` are numpy's maximum and
minimum against a bound (a NaN value stays NaN; of two equal values the second, the
bound, as numpy's SIMD loops give).
"""

from __future__ import annotations

import os

import numpy as np

from faceclean.filters.base import MAX_ABS
from faceclean.learned.checkpoint import RATE_A_MAX, RATE_TAU0

try:  # the optional ``fast`` extra; FACECLEAN_NUMBA=0 keeps it off (filters/compiled.py)
    if os.environ.get("FACECLEAN_NUMBA", "").strip() == "0":
        raise ImportError("FACECLEAN_NUMBA=0")
    from numba import njit
except ImportError:  # pragma: no cover - exercised where numba is absent
    njit = None

_FAST = {"reassoc", "contract"}  # reorder sums (vectorise the dots); no nnan/ninf


def available() -> bool:
    """Whether the compiled kernel can run here."""
    return njit is not None


def _tanh(x):
    """tanh in float32 arithmetic, |error| <= 3.3e-7 (Eigen's rational approximation)."""
    c = np.float32(7.99881172180175781)  # tanh is 1 - 2e-7 beyond this
    x = min(max(x, -c), c)
    x2 = x * x
    p = x2 * np.float32(-2.76076847742355e-16) + np.float32(2.00018790482477e-13)
    p = p * x2 + np.float32(-8.60467152213735e-11)
    p = p * x2 + np.float32(5.12229709037114e-08)
    p = p * x2 + np.float32(1.48572235717979e-05)
    p = p * x2 + np.float32(6.37261928875436e-04)
    p = p * x2 + np.float32(4.89352455891786e-03)
    q = x2 * np.float32(1.19825839466702e-06) + np.float32(1.18534705686654e-04)
    q = q * x2 + np.float32(2.26843463243900e-03)
    q = q * x2 + np.float32(4.89352518554385e-03)
    return x * p / q


def _step(dt, zs, cs, top, g, cols, hv, wts, head_t, lo, hi, mode, x, out):
    """One step for every stream, in place (lstm_kernel's layout: one column per stream);
    False, with nothing changed, if ``x`` holds a non-finite or absurd value (rule 2 of
    filters/base.py: beyond +-MAX_ABS).

    dt (1, S) s; zs, cs, top: the workspace's buffers; g (4H, S), cols (S, rows of
    zs[0]), hv (H, S): scratch; wts[l] (4H, rows of zs[l]) fused weights, gates
    (i, f, o, g), the (i, f, o) rows pre-scaled by 1/2; head_t (M, H + 1), or (2M, H + 1)
    for a gated (mode 1: x̂' = (1 + tanh a) x_c + b, rows a then b) or rate head (mode 2:
    x̂' = (1 - exp(-dt / tau)) x_c + b, tau = RATE_TAU0 e^a); mode 0 additive; x (S, M) the
    new frames (any float dtype); out (S, M) receives x̂[n+1]. The arguments before x
    do not change between steps (the caller keeps them in one tuple). Each weight row is read once
    for all S streams.
    """
    S, M = x.shape
    for s in range(S):
        for m in range(M):
            if not abs(x[s, m]) <= MAX_ABS:  # NaN fails too
                return False
    H = cs[0].shape[0]
    L = len(zs)
    a_max = np.float32(RATE_A_MAX)
    inv_tau0 = np.float32(1.0 / RATE_TAU0)
    half = np.float32(0.5)
    z0 = zs[0]
    for s in range(S):
        for m in range(M):
            z0[2 * M + m, s] = (np.float32(x[s, m]) - z0[m, s]) / dt[0, s]  # Eq. 2
    for layer in range(L):
        z, c, w = zs[layer], cs[layer], wts[layer]
        width = z.shape[0]
        for s in range(S):
            for k in range(width):
                cols[s, k] = z[k, s]  # [in | h | 1] of stream s, contiguous
        for n in range(4 * H):  # gates = W^T [in | h | 1]
            for s in range(S):
                acc = np.float32(0.0)
                for k in range(width):
                    acc += w[n, k] * cols[s, k]
                g[n, s] = acc
        for n in range(4 * H):
            for s in range(S):
                g[n, s] = _tanh(g[n, s])
        for j in range(H):
            for s in range(S):
                i = half + half * g[j, s]  # sigmoid(a) = (1 + tanh(a / 2)) / 2
                f = half + half * g[H + j, s]
                cj = f * c[j, s] + i * g[3 * H + j, s]
                c[j, s] = cj
                hv[j, s] = _tanh(cj)
        off = width - 1 - H  # where h_l sits in z
        nxt = zs[layer + 1] if layer + 1 < L else top
        for j in range(H):
            for s in range(S):
                h = (half + half * g[2 * H + j, s]) * hv[j, s]  # h = o tanh(c)
                z[off + j, s] = h
                nxt[j, s] = h + cols[s, j] if layer > 0 else h  # residual for l >= 1
    for s in range(S):
        for k in range(H + 1):
            cols[s, k] = top[k, s]
    for m in range(M):
        for s in range(S):
            acc = np.float32(0.0)
            for k in range(H + 1):
                acc += head_t[m, k] * cols[s, k]
            if mode != 0:  # acc is the gain logit a; x̂'[n] = g x_c + b
                b = np.float32(0.0)
                for k in range(H + 1):
                    b += head_t[M + m, k] * cols[s, k]
                if mode == 1:
                    gain = np.float32(1.0) + _tanh(acc)
                else:  # one-pole gain, tau = RATE_TAU0 e^a
                    a = min(max(acc, -a_max), a_max)
                    gain = np.float32(1.0) - np.exp(-dt[0, s] * inv_tau0 * np.exp(-a))
                dm = gain * z0[2 * M + m, s] + b
            else:
                dm = z0[2 * M + m, s] + acc  # x̂'[n] = x_c + correction
            z0[M + m, s] = dm
            ym = min(max(z0[m, s] + dt[0, s] * dm, lo), hi)  # integrate, clamp
            z0[m, s] = ym
            out[s, m] = ym
    return True


def _run(dt, zs, cs, top, g, cols, hv, wts, head_t, lo, hi, mode, xs, dts, out):
    """``_step`` over frames xs (N, M) with dts (N,) s, one stream; out (N, M) gets
    x̂ after each. The frames must be sane (the caller checked); dt (1, 1) scratch."""
    for n in range(xs.shape[0]):
        dt[0, 0] = dts[n]
        step(dt, zs, cs, top, g, cols, hv, wts, head_t, lo, hi, mode, xs[n : n + 1], out[n : n + 1])


def _trees(f, groups, feat, thr, val, order, depth, out):
    """Leaf sums of every tree for every (stream, channel), in place: f (S, F, M) the
    feature-major features, feature F (one past f's) is the channel's group, groups (M,);
    feat, thr (T, 2^D - 1) (left when not x > thr: NaN goes left); val (T, 2^D); order
    (T,) the output row of each tree; out (S, K, M) zeros, gets the sums."""
    S, F, M = f.shape
    T, n_in = feat.shape
    for s in range(S):
        for m in range(M):
            for t in range(T):
                node = 0
                for _ in range(depth):
                    j = feat[t, node]
                    v = f[s, j, m] if j < F else groups[m]
                    node = 2 * node + (2 if v > thr[t, node] else 1)
                out[s, order[t], m] += val[t, node - n_in]


def _lstm_cell(g, c):
    """kernel.step_numpy's gate arithmetic after tanh, in its order (the same bits): g
    (4H, S) tanh of the (i, f, o) logits / 2 and of g's; sigmoid = tanh * 1/2 + 1/2 for
    i, f, o (o written back into g); c (H, S) = c f + i g in place."""
    H, S = c.shape
    half = np.float32(0.5)
    for j in range(H):
        for s in range(S):
            i = g[j, s] * half + half
            f = g[H + j, s] * half + half
            g[2 * H + j, s] = g[2 * H + j, s] * half + half
            c[j, s] = c[j, s] * f + i * g[3 * H + j, s]


def _lstm_out(g, th, h, nxt, z, layer):
    """h = o tanh(c) (th (H, S) = tanh(c)); nxt = h, plus the layer's input z[:H] (the
    residual) for layer >= 1, as kernel.step_numpy."""
    H, S = th.shape
    for j in range(H):
        for s in range(S):
            v = g[2 * H + j, s] * th[j, s]
            h[j, s] = v
            nxt[j, s] = v + z[j, s] if layer > 0 else v


def _max(a, b):
    return a if not a <= b else b  # b a bound, never NaN: a NaN a stays


def _min(a, b):
    return a if not a >= b else b


def _fc_features(f_old, x, dt, big, lo, hi, f, h):
    """FC's features of a step (derivative_net.FullyConnected), for S streams: f_old, f
    (S, 1 + 2K, M) the last and the new feature-major state [d^(0..K)[n], d^(1..K)[n-1]]
    (float64), x (S, M) the new frames in model order, dt (S, 1) s; d^(k) the backward
    difference clipped to +-big. h (S, (1 + 2K) M) float32 gets the features clipped to
    [lo, hi] (F M,) float32, compared in float64, as layer 0 reads them."""
    S, F, M = f.shape
    K = (F - 1) // 2
    for s in range(S):
        for m in range(M):
            f[s, 0, m] = x[s, m]
        for k in range(1, K + 1):
            for m in range(M):
                d = (f[s, k - 1, m] - f_old[s, k - 1, m]) / dt[s, 0]
                f[s, k, m] = _min(_max(d, -big), big)
                f[s, K + k, m] = f_old[s, k, m]
        for j in range(F):
            for m in range(M):
                v = np.float32(_max(f[s, j, m], np.float64(lo[j * M + m])))
                h[s, j * M + m] = _min(v, hi[j * M + m])


def _fc_blend(o, b, os_, om, f, r_old, dt, alpha, lo, hi, r_new):
    """FC's output and blend, for S streams: o (S, K M) float32 the last layer's product,
    b its bias; the prediction X̂^(k+1) = float64(o + b) os_ + om (K M,) order-major;
    r_new[s, k] = a (r_old + dt X̂^(k+1)) + (1 - a) X̂^(k) (derivative_net.blend),
    X̂^(0) = f[s, 0], a = alpha[s]; X_r^(0) clipped to [lo, hi]. r_old, r_new (S, K, M)."""
    S, K, M = r_new.shape
    below = np.empty(M)  # X̂^(k) of the stream, then X̂^(k+1)
    for s in range(S):
        a, d = alpha[s], dt[s, 0]
        for m in range(M):
            below[m] = f[s, 0, m]
        for k in range(K):
            for m in range(M):
                j = k * M + m
                p = np.float64(o[s, j] + b[j]) * os_[j] + om[j]
                r_new[s, k, m] = a * (r_old[s, k, m] + d * p) + (1.0 - a) * below[m]
                below[m] = p
        for m in range(M):
            r_new[s, 0, m] = _min(_max(r_new[s, 0, m], lo), hi)


if njit is not None:
    trees = njit(boundscheck=False, nogil=True, cache=True)(_trees)
    _max = njit(inline="always", cache=True)(_max)
    _min = njit(inline="always", cache=True)(_min)
    fc_features = njit(boundscheck=False, nogil=True, cache=True)(_fc_features)
    lstm_cell = njit(boundscheck=False, nogil=True, cache=True)(_lstm_cell)
    lstm_out = njit(boundscheck=False, nogil=True, cache=True)(_lstm_out)
    fc_blend = njit(boundscheck=False, nogil=True, cache=True)(_fc_blend)
    _tanh = njit(fastmath=_FAST, inline="always", cache=True)(_tanh)
    step = njit(fastmath=_FAST, boundscheck=False, nogil=True, cache=True)(_step)
    run = njit(boundscheck=False, nogil=True, cache=True)(_run)
else:  # pragma: no cover
    step = run = trees = fc_features = fc_blend = lstm_cell = lstm_out = None
