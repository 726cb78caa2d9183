"""The learned cleaner's torch-free runtime: one causal LSTM step in numpy (SPEC section 2).

One step, when frame n+1 arrives dt[n] seconds after frame n (K = 1):

    x_c   = (x_i[n+1] - x̂[n]) / dt                      # Eq. 2: corrective derivative
    f     = [x̂[n], x̂'[n-1], x_c]                        # (S, 3M), scaled inside layer 0
    h_0   = LSTM_0(f);  o_l = h_l + o_{l-1} for l >= 1   # residual where sizes match
    x̂'[n] = x_c + out_scale * dense(o_{L-1})             # output residual
    x̂[n+1] = clamp(x̂[n] + dt x̂'[n], value_range)        # integrate

Speed: the weights are fused (lstm_weights.Fused): one matrix product per layer with the
state laid out beside the input in one preallocated float32 row buffer
[x̂ | x̂' | x_c | h_0 | 1], and S streams are S rows of the same products. When every
stream advances normally (the common case) ``step`` runs that kernel in place with no
array allocation but the returned frame; anything else (first frame, missing values,
a gap, a repeated timestamp) takes the base class's generic rules, which a test proves
equal on the common case.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.filters import learned_jit
from faceclean.filters.base import State, StreamCleaner
from faceclean.filters.channel_map import ChannelMap
from faceclean.filters.lstm_weights import Fused, LSTMWeights


def default_model_path():
    """The shipped model file (it may not exist yet)."""
    from faceclean.settings import MODELS

    return MODELS / "default.npz"


class _Workspace:
    """Preallocated float32 buffers for S streams; the state lives inside them."""

    def __init__(self, S: int, M: int, H: int, n_layers: int) -> None:
        self.streams, self.M, self.H = S, M, H
        f32 = np.float32
        z0 = np.zeros((S, 3 * M + H + 1), f32)  # [x̂ | x̂' | x_c | h_0 | 1]
        zl = [np.zeros((S, 2 * H + 1), f32) for _ in range(1, n_layers)]  # [in | h_l | 1]
        self.z = (z0, *zl)
        self.c = tuple(np.zeros((S, H), f32) for _ in range(n_layers))
        self.top = np.zeros((S, H + 1), f32)  # [o_{L-1} | 1], input of the head
        for z in (*self.z, self.top):
            z[:, -1] = 1.0
        self.gates = np.zeros((S, 4 * H), f32)  # (i, f, o, g)
        self.tmp = np.zeros((S, H), f32)
        self.hv = np.zeros(H, f32)  # scratch of the compiled kernel
        self.flip = False  # weight-row order of the compiled kernel (see learned_jit)
        self.out = np.zeros((S, M))  # x̂[n+1] in float64, model channel order
        self.head = np.zeros((S, M), f32)
        self.x = np.zeros((S, M), f32)  # the new input frame, model channel order
        self.dt = np.zeros((S, 1), f32)  # s
        self.dt64 = np.zeros(S)  # s, scratch for the time checks
        self.y, self.d, self.xc = z0[:, :M], z0[:, M : 2 * M], z0[:, 2 * M : 3 * M]
        self.h = [z0[:, 3 * M : 3 * M + H]] + [z[:, H : 2 * H] for z in self.z[1:]]

    def state(self) -> State:
        """Copies of the state: (x̂, x̂', h_0, c_0, h_1, c_1, ...), each (S, ·)."""
        parts = [self.y, self.d]
        for h, c in zip(self.h, self.c, strict=True):
            parts += [h, c]
        return tuple(p.copy() for p in parts)

    def load(self, state: State) -> None:
        """Copy a state tuple (as from ``state()``) into the buffers."""
        targets = [self.y, self.d]
        for h, c in zip(self.h, self.c, strict=True):
            targets += [h, c]
        for dst, src in zip(targets, state, strict=True):
            np.copyto(dst, src, casting="unsafe")


def _kernel_numpy(ws: _Workspace, fused: Fused, lo: float, hi: float) -> None:
    """Advance every row of ``ws`` by ws.dt with input ws.x, in place (no allocation)."""
    H = ws.H
    np.subtract(ws.x, ws.y, out=ws.xc)
    np.divide(ws.xc, ws.dt, out=ws.xc)  # Eq. 2
    g = ws.gates
    sig, cand = g[:, : 3 * H], g[:, 3 * H :]  # (i, f, o), g
    i, f, o = g[:, :H], g[:, H : 2 * H], g[:, 2 * H : 3 * H]
    n = len(ws.z)
    for layer in range(n):
        z, c, h = ws.z[layer], ws.c[layer], ws.h[layer]
        np.matmul(z, fused.layers[layer], out=g)  # (S, 4H) = [in | h | 1] @ W
        np.tanh(g, out=g)  # (i, f, o) rows were pre-scaled by 1/2:
        np.multiply(sig, 0.5, out=sig)
        np.add(sig, 0.5, out=sig)  # sigmoid(a) = (1 + tanh(a / 2)) / 2
        np.multiply(c, f, out=c)
        np.multiply(i, cand, out=ws.tmp)
        np.add(c, ws.tmp, out=c)  # c = f c + i g
        np.tanh(c, out=ws.tmp)
        np.multiply(o, ws.tmp, out=h)  # h = o tanh(c)
        nxt = ws.z[layer + 1][:, :H] if layer + 1 < n else ws.top[:, :H]
        if layer == 0:
            np.copyto(nxt, h)
        else:
            np.add(h, z[:, :H], out=nxt)  # residual around layers l >= 1
    np.matmul(ws.top, fused.head, out=ws.head)  # out_scale * dense(o), (S, M)
    np.add(ws.xc, ws.head, out=ws.d)  # x̂'[n] = x_c + correction
    np.multiply(ws.d, ws.dt, out=ws.head)
    np.add(ws.y, ws.head, out=ws.y)  # x̂[n+1] = x̂[n] + dt x̂'[n]
    np.maximum(ws.y, lo, out=ws.y)
    np.minimum(ws.y, hi, out=ws.y)


class Learned(StreamCleaner):
    """The paper's causal LSTM cleaner, from a ``faceclean-lstm/1`` checkpoint (.npz).

    ``path`` None means the shipped default model. The model's channels are matched to
    ``names`` by canonical name: input channels the model lacks pass through untouched;
    model channels the input lacks are fed their own last output (no correction).
    """

    name = "lstm"
    jit_max_streams: int = 8  # above this, numpy's BLAS products beat the per-row loops

    def __init__(
        self,
        path: str | os.PathLike | None = None,
        *,
        names: Sequence[str] = ARKIT52,
        weights: LSTMWeights | None = None,
        max_gap: float = 0.5,
        kernel: str = "auto",
    ) -> None:
        if weights is None:
            p = default_model_path() if path is None else path
            if path is None and not p.is_file():
                raise FacecleanError("no shipped model yet (models/default.npz); give a path")
            weights = LSTMWeights.load(p)
        if weights.K != 1:
            raise FacecleanError(f"the runtime steps K = 1 models only (this one: K = {weights.K})")
        if not max_gap > 0:
            raise FacecleanError(f"max_gap must be > 0 s (got {max_gap})")
        if kernel not in ("auto", "numpy", "numba"):
            raise FacecleanError(f"kernel must be auto, numpy or numba (got {kernel!r})")
        if kernel == "numba" and not learned_jit.available():
            raise FacecleanError("kernel='numba' needs numba (pip install 'faceclean[fast]')")
        self.kernel = (
            kernel if kernel != "auto" else "numba" if learned_jit.available() else "numpy"
        )
        self.weights = weights
        self.fused = weights.fused(half_sigmoid=True)
        self._wts = tuple(np.ascontiguousarray(w.T) for w in self.fused.layers)  # (4H, in)
        self._head_t = np.ascontiguousarray(self.fused.head.T)  # (M, H + 1)
        self.max_gap = float(max_gap)
        self.names = tuple(names)
        self.lo, self.hi = (np.float32(v) for v in weights.value_range)
        self.map = ChannelMap(weights.channels, self.names)
        self.reset()

    @property
    def state_bytes(self) -> int:
        """Bytes of recurrent state per stream (x̂, x̂', h and c of every layer; float32)."""
        M, H = len(self.weights.channels), self.weights.hidden
        return 4 * (2 * M + 2 * H * self.weights.layers)

    def reset(self) -> None:
        super().reset()
        self._ws: _Workspace | None = None

    def _run(self, ws: _Workspace, x: np.ndarray, out: np.ndarray) -> bool:
        """Advance every stream by ws.dt with frames x (S, M) in model order, writing
        x̂[n+1] to ``out`` (S, M); False, with nothing changed, if x is not all finite.
        Compiled for a few streams, numpy (BLAS matrix products) for many."""
        if self.kernel == "numba" and ws.streams <= self.jit_max_streams:
            ws.flip = not ws.flip
            return learned_jit.step(
                x, ws.dt, ws.z, ws.c, ws.top, ws.gates[0], ws.hv,
                self._wts, self._head_t, self.lo, self.hi, out, ws.flip,
            )  # fmt: skip
        if x is not ws.x:
            flat = x.reshape(-1)
            if not math.isfinite(float(np.dot(flat, flat))):  # NaN/inf (or overflow)
                return False
            np.copyto(ws.x, x, casting="unsafe")
        _kernel_numpy(ws, self.fused, self.lo, self.hi)
        np.copyto(out, ws.y)
        return True

    # -- the generic path (base class rules) -----------------------------------------------

    def _start(self, x: np.ndarray) -> State:
        S, M, H = x.shape[0], len(self.weights.channels), self.weights.hidden
        y = np.zeros((S, M), np.float32)
        self.map.gather(x, y, y)  # channels the input lacks start at 0
        zeros = [np.zeros((S, H), np.float32) for _ in range(2 * self.weights.layers)]
        return (y, np.zeros((S, M), np.float32), *zeros)

    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        ws = self._ws
        ws.load(state)
        self.map.gather(x, ws.y, ws.x)
        np.copyto(ws.dt, dt, casting="unsafe")
        self._run(ws, ws.x, ws.out)
        return ws.state(), self.map.scatter(x, ws.y)

    def _generic_step(self, frame: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        x = np.array(frame, dtype=np.float64, ndmin=1)
        S = 1 if x.ndim == 1 else x.shape[0]
        if self._ws is None or self._ws.streams != S:
            M = len(self.weights.channels)
            self._ws = _Workspace(S, M, self.weights.hidden, self.weights.layers)
        if self._state is not None:
            self._state = self._ws.state()
        y = super().step(frame, t)
        if self._state is not None:
            self._ws.load(self._state)
        return y

    # -- the fast path ---------------------------------------------------------------------

    def step(self, frame: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        """Clean one frame (M,) at t s, or S frames (S, M) at t (S,); see filters.base."""
        ws = self._ws
        if ws is None or self._state is None:
            return self._generic_step(frame, t)
        x = np.asarray(frame)
        last = self._y
        single = x.ndim == 1
        if x.shape[-1:] != last.shape[1:] or (
            ws.streams != 1 if single else x.shape[0] != ws.streams
        ):
            return self._generic_step(frame, t)
        if single:
            if not isinstance(t, float | int | np.floating):
                return self._generic_step(frame, t)
            tf = float(t)
            dt = tf - float(self._t[0])
            if not (0.0 < dt <= self.max_gap):  # NaN fails too
                return self._generic_step(frame, t)
            ws.dt[0, 0] = dt
        else:
            dt = np.subtract(t, self._t, out=ws.dt64)
            if not (np.all(dt > 0.0) and np.all(dt <= self.max_gap)):
                return self._generic_step(frame, t)
            np.copyto(ws.dt[:, 0], dt, casting="unsafe")
        if x.dtype.kind != "f":
            return self._generic_step(frame, t)
        x2 = x.reshape(ws.streams, -1)
        if self.map.identity:
            if not self._run(ws, x2, last):
                return self._generic_step(frame, t)  # rule 2: the generic path
        else:
            flat = x.reshape(-1)
            if not math.isfinite(float(np.dot(flat, flat))):
                return self._generic_step(frame, t)
            self.map.gather(x2, ws.y, ws.x)
            self._run(ws, ws.x, ws.out)
            last[...] = self.map.scatter(x2, ws.y)
        if single:
            self._t[0] = tf
        else:
            np.copyto(self._t, np.broadcast_to(t, self._t.shape))
        return last[0].copy() if single else last.copy()
