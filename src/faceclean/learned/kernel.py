"""The learned runtime's step on preallocated buffers: the workspace and the numpy kernel.

Layout, one column per stream (S streams): every buffer is (rows, S), so each gate,
state or feature block is a contiguous run of rows and every ufunc below works on
contiguous memory (numpy copies strided operands, which would allocate per step):

    z[0]   (3M + H + 1, S)  [x̂ | x̂' | x_c | h_0 | 1]   features and layer 0's h
    z[l]   (2H + 1, S)      [o_{l-1} | h_l | 1]          l >= 1
    c[l]   (H, S)           cell state
    top    (H + 1, S)       [o_{L-1} | 1]                input of the head
    gates  (4H, S)          (i, f, o, g)

With the fused weights W_l^T (4H, rows of z[l]) one matrix product per layer gives every
gate of every stream: gates = W_l^T z[l]; the head is head^T (M, H + 1) top, or
(2M, H + 1) top = [a | b] for a gated output head: x̂' = (1 + tanh a) x_c + b, or a
rate one: x̂' = (1 - exp(-dt / tau)) x_c + b, tau = RATE_TAU0 e^a.
"""

from __future__ import annotations

import numpy as np

from faceclean.filters.base import State
from faceclean.learned.checkpoint import RATE_A_MAX, RATE_TAU0

HEADS = {"additive": 0, "gated": 1, "rate": 2}  # output head -> the kernels' ``mode``
_A_MAX = np.float32(RATE_A_MAX)
_NEG_INV_TAU0 = np.float32(-1.0 / RATE_TAU0)  # 1/s


class Workspace:
    """Preallocated float32 buffers for S streams; the state lives inside them."""

    def __init__(self, S: int, M: int, H: int, n_layers: int) -> None:
        self.streams, self.M, self.H = S, M, H
        f32 = np.float32
        z0 = np.zeros((3 * M + H + 1, S), f32)
        zl = [np.zeros((2 * H + 1, S), f32) for _ in range(1, n_layers)]
        self.z = (z0, *zl)
        self.c = tuple(np.zeros((H, S), f32) for _ in range(n_layers))
        self.top = np.zeros((H + 1, S), f32)
        for z in (*self.z, self.top):
            z[-1] = 1.0  # the bias row
        self.gates = np.zeros((4 * H, S), f32)
        self.tmp = np.zeros((H, S), f32)
        self.head = np.zeros((2 * M, S), f32)  # head output [correction] or [a | b]
        self.x = np.zeros((M, S), f32)  # the new frames, model channel order
        self.xs = np.zeros((S, M), f32)  # the same, one row per stream (gathered)
        self.out = np.zeros((S, M))  # x̂[n+1], float64, one row per stream
        self.dt = np.zeros((1, S), f32)  # s
        self.dtm = np.zeros((M, S), f32)  # s, dt broadcast (contiguous)
        self.dt64 = np.zeros(S)  # s, scratch for the time checks
        self.cols = np.zeros((S, 3 * M + H + 1), f32)  # compiled kernel: z[l] per stream
        self.jit_args: tuple = ()  # compiled kernel: its fixed arguments (set by Learned)
        self.y, self.d, self.xc = z0[:M], z0[M : 2 * M], z0[2 * M : 3 * M]
        self.h = [z0[3 * M : 3 * M + H]] + [z[H : 2 * H] for z in self.z[1:]]

    def _parts(self) -> list[np.ndarray]:
        parts = [self.y, self.d]
        for h, c in zip(self.h, self.c, strict=True):
            parts += [h, c]
        return parts

    def state(self) -> State:
        """Copies of the state, one row per stream: (x̂, x̂', h_0, c_0, h_1, c_1, ...)."""
        return tuple(p.T.copy() for p in self._parts())

    def load(self, state: State) -> None:
        """Copy a state tuple (as from ``state()``) into the buffers."""
        for dst, src in zip(self._parts(), state, strict=True):
            np.copyto(dst, src.T, casting="unsafe")


def step_numpy(
    ws: Workspace,
    wts: tuple[np.ndarray, ...],
    head_t: np.ndarray,
    lo: float,
    hi: float,
    mode: int = 0,
    fused: tuple | None = None,
) -> None:
    """Advance every stream by ws.dt with frames ws.x, in place, allocating nothing.

    wts[l]: (4H, rows of z[l]) fused weights, the (i, f, o) rows pre-scaled by 1/2;
    head_t: (M, H + 1) with out_scale folded in, or (2M, H + 1) for a gated output
    head (gain logits a, then out_scale b); [lo, hi]: the value range; ``mode``: the
    output head (HEADS); ``fused``: learned/jit.py's (lstm_cell, lstm_out), the gate
    arithmetic after each tanh in one compiled pass each (the same bits), or None.
    """
    H, M = ws.H, ws.M
    half = np.float32(0.5)
    np.copyto(ws.dtm, ws.dt)  # (M, S)
    np.subtract(ws.x, ws.y, out=ws.xc)
    np.divide(ws.xc, ws.dtm, out=ws.xc)  # Eq. 2: x_c = (x_i[n+1] - x̂[n]) / dt
    g = ws.gates
    sig, cand = g[: 3 * H], g[3 * H :]  # (i, f, o), g
    i, f, o = g[:H], g[H : 2 * H], g[2 * H : 3 * H]
    n = len(ws.z)
    for layer in range(n):
        z, c, h = ws.z[layer], ws.c[layer], ws.h[layer]
        np.matmul(wts[layer], z, out=g)  # (4H, S) = W^T [in | h | 1]
        np.tanh(g, out=g)  # the (i, f, o) rows were pre-scaled by 1/2:
        nxt = ws.z[layer + 1][:H] if layer + 1 < n else ws.top[:H]
        if fused is not None:  # the lines below, two passes instead of seven
            fused[0](g, c)
            np.tanh(c, out=ws.tmp)
            fused[1](g, ws.tmp, h, nxt, z, layer)
            continue
        np.multiply(sig, half, out=sig)
        np.add(sig, half, out=sig)  # sigmoid(a) = (1 + tanh(a / 2)) / 2
        np.multiply(c, f, out=c)
        np.multiply(i, cand, out=ws.tmp)
        np.add(c, ws.tmp, out=c)  # c = f c + i g
        np.tanh(c, out=ws.tmp)
        np.multiply(o, ws.tmp, out=h)  # h = o tanh(c)
        if layer == 0:
            np.copyto(nxt, h)
        else:
            np.add(h, z[:H], out=nxt)  # residual around layers l >= 1
    out = ws.head[: head_t.shape[0]]  # (M, S) or (2M, S), contiguous rows
    np.matmul(head_t, ws.top, out=out)  # out_scale * dense(o), or [a | out_scale b]
    if mode == 0:
        np.add(ws.xc, out, out=ws.d)  # x̂'[n] = x_c + correction
    else:
        a, b = out[:M], out[M:]
        if mode == 1:
            np.tanh(a, out=a)
            np.add(a, np.float32(1.0), out=a)  # g = 1 + tanh a
        else:
            np.minimum(a, _A_MAX, out=a)
            np.maximum(a, -_A_MAX, out=a)
            np.negative(a, out=a)
            np.exp(a, out=a)
            np.multiply(a, ws.dtm, out=a)
            np.multiply(a, _NEG_INV_TAU0, out=a)  # -dt / tau
            np.exp(a, out=a)
            np.subtract(np.float32(1.0), a, out=a)  # g = 1 - exp(-dt / tau)
        np.multiply(a, ws.xc, out=a)
        np.add(a, b, out=ws.d)  # x̂'[n] = g x_c + out_scale b
    tmp = ws.head[:M]
    np.multiply(ws.d, ws.dtm, out=tmp)
    np.add(ws.y, tmp, out=ws.y)  # x̂[n+1] = x̂[n] + dt x̂'[n]
    np.maximum(ws.y, lo, out=ws.y)
    np.minimum(ws.y, hi, out=ws.y)
