"""The learned cleaner's torch-free runtime: one causal LSTM step in numpy (SPEC section 2).

One step, when frame n+1 arrives dt[n] seconds after frame n (K = 1):

    x_c   = (x_i[n+1] - x̂[n]) / dt                      # Eq. 2: corrective derivative
    f     = [x̂[n], x̂'[n-1], x_c]                        # (S, 3M), scaled inside layer 0
    h_0   = LSTM_0(f);  o_l = h_l + o_{l-1} for l >= 1   # residual where sizes match
    x̂'[n] = x_c + out_scale * dense(o_{L-1})             # output residual
          = g x_c + out_scale * b, [a | b] = dense(o_{L-1})   # "gated", "rate" heads
            g = 1 + tanh a (gated) or 1 - exp(-dt / (RATE_TAU0 e^a)) (rate)
    x̂[n+1] = clamp(x̂[n] + dt x̂'[n], value_range)        # integrate

Speed: the weights are fused (checkpoint.Fused): one matrix product per layer with the
state laid out beside the input in one preallocated float32 buffer [x̂ | x̂' | x_c | h_0 | 1]
(kernel.Workspace), S streams being S columns of the same products; a compiled
kernel (learned/jit.py, when numba is installed) serves a few streams. When every
stream advances normally (the common case) ``step`` runs that kernel in place with no
array allocation but the returned frame; anything else (first frame, missing values,
a gap, a repeated timestamp) takes the base class's generic rules; which frames are
common is decided by filters/base.py's own ``advances`` and ``time_rules``, and a test
proves the two paths equal on the common case.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from faceclean.animation import Animation
from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.filters.base import (
    BLOCK,
    MAX_ABS,
    MAX_GAP,
    State,
    StreamCleaner,
    advances,
    gap_seconds,
    time_rules,
)
from faceclean.learned import jit
from faceclean.learned.checkpoint import LSTMWeights
from faceclean.learned.kernel import HEADS, Workspace, step_numpy

_SCALAR = (float, int, np.floating)


def default_model_path():
    """The shipped model file (it may not exist yet)."""
    from faceclean.settings import MODELS

    return MODELS / "lstm.npz"  # the paper's LSTM: a shipped baseline, not the default


class Learned(StreamCleaner):
    """The paper's causal LSTM cleaner, from a ``faceclean-lstm/1`` checkpoint (.npz).

    ``model`` (.npz) None: the shipped default model. The model's channels are matched to
    ``names`` by canonical name: input channels the model lacks pass through untouched;
    model channels the input lacks are fed their own last output (no correction).
    """

    name = "lstm"
    jit_max_streams: int = 4  # above, numpy's BLAS products win (docs/BENCHMARKS.md)

    def __init__(
        self,
        model: str | os.PathLike | None = None,
        *,
        names: Sequence[str] = ARKIT52,
        weights: LSTMWeights | None = None,
        max_gap: float = MAX_GAP,
        kernel: str = "auto",
    ) -> None:
        if weights is None:
            weights = LSTMWeights.load(default_model_path() if model is None else model)
        if weights.K != 1:
            raise FacecleanError(f"the runtime steps K = 1 models only (this one: K = {weights.K})")
        self.max_gap = gap_seconds(max_gap)
        if kernel not in ("auto", "numpy", "numba"):
            raise FacecleanError(f"kernel must be auto, numpy or numba (got {kernel!r})")
        if kernel == "numba" and not jit.available():
            raise FacecleanError("kernel='numba' needs numba (pip install 'faceclean[fast]')")
        self.kernel = kernel if kernel != "auto" else "numba" if jit.available() else "numpy"
        # many streams, numba: numpy's products and tanh, the gates compiled (same bits)
        self._fused = (jit.lstm_cell, jit.lstm_out) if self.kernel == "numba" else None
        self.weights = weights
        fused = weights.fused(half_sigmoid=True)
        self._wts = tuple(np.ascontiguousarray(w.T) for w in fused.layers)  # (4H, in + H + 1)
        self._head_t = np.ascontiguousarray(fused.head.T)  # (M, or 2M gated/rate, H + 1)
        self._mode = HEADS[weights.output]
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
        self._ws: Workspace | None = None

    def _run(self, ws: Workspace, x: np.ndarray, out: np.ndarray) -> bool:
        """Advance every stream by ws.dt with frames x (S, M) in model order, writing
        x̂[n+1] to ``out`` (S, M); False, with nothing changed, if x is not all finite.
        Compiled for a few streams, numpy (BLAS matrix products) for many."""
        if self.kernel == "numba" and ws.streams <= self.jit_max_streams:
            return jit.step(*ws.jit_args, x, out)
        flat = x.reshape(-1)
        if not _sane(flat):  # NaN/inf/absurd: base rules
            return False
        np.copyto(ws.x, x.T, casting="unsafe")
        step_numpy(ws, self._wts, self._head_t, self.lo, self.hi, self._mode, self._fused)
        np.copyto(out, ws.y.T)
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
        self.map.gather(x, ws.y.T, ws.xs)
        np.copyto(ws.dt, dt.T, casting="unsafe")
        self._run(ws, ws.xs, ws.out)
        return ws.state(), self.map.scatter(x, ws.out)

    def _generic_step(self, frame: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        x = np.array(frame, dtype=np.float64, ndmin=1)
        S = 1 if x.ndim == 1 else x.shape[0]
        if self._ws is None or self._ws.streams != S:
            M = len(self.weights.channels)
            ws = self._ws = Workspace(S, M, self.weights.hidden, self.weights.layers)
            ws.jit_args = (ws.dt, ws.z, ws.c, ws.top, ws.gates, ws.cols, ws.tmp)
            ws.jit_args += (self._wts, self._head_t, self.lo, self.hi, self._mode)
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
            if not isinstance(t, _SCALAR):
                return self._generic_step(frame, t)
            tf = float(t)
            dt = tf - float(self._t[0])
            if not advances(dt, self.max_gap):  # rules 3-4 (NaN too): the generic path
                return self._generic_step(frame, t)
            ws.dt[0, 0] = dt
        else:
            dt = np.subtract(t, self._t, out=ws.dt64)
            if not advances(dt, self.max_gap).all():
                return self._generic_step(frame, t)
            np.copyto(ws.dt[0], dt, casting="unsafe")
        if x.dtype.kind != "f":
            return self._generic_step(frame, t)
        x2 = x.reshape(ws.streams, -1)
        if self.map.identity:
            if not self._run(ws, x2, last):
                return self._generic_step(frame, t)  # rule 2: the generic path
        else:
            flat = x.reshape(-1)
            if not _sane(flat):
                return self._generic_step(frame, t)
            self.map.gather(x2, ws.y.T, ws.xs)
            self._run(ws, ws.xs, ws.out)
            last[...] = self.map.scatter(x2, ws.out)
        if single:
            self._t[0] = tf
        else:
            np.copyto(self._t, np.broadcast_to(t, self._t.shape))
        return last[0].copy() if single else last.copy()

    # -- whole clips -----------------------------------------------------------------------

    def clean(self, anim: Animation) -> Animation:
        """Reset, then step every valid frame (filters.base); runs of ordinary frames
        (every value sane, advancing by the base's ``time_rules``) go through the kernel
        in one call, with the same numbers as stepping them one by one (tested)."""
        if not self.map.identity or anim.n_channels != len(self.names):
            return super().clean(anim)
        self.reset()
        out = np.full_like(anim.values, np.nan)
        idx = np.flatnonzero(anim.valid)
        t = anim.times[idx]
        sane = np.zeros((2, len(idx)), bool)  # (2, V): some value sane, every value sane
        for a in range(0, len(idx), BLOCK):  # in blocks: no temporary as large as the take
            with np.errstate(invalid="ignore"):
                cells = np.abs(anim.values[idx[a : a + BLOCK]]) <= MAX_ABS  # rule 2's cells
            sane[0, a : a + BLOCK], sane[1, a : a + BLOCK] = cells.any(axis=1), cells.all(axis=1)
        _, advance, dt = time_rules(t[None], ~sane[:1], self.max_gap)
        ok = advance[0] & sane[1]  # the rest: the generic step's rules 1-4
        dt = dt[0]  # s, since the last accepted frame
        for a in range(0, len(idx), BLOCK):
            x, k, end = anim.values[idx[a : a + BLOCK]], a, min(a + BLOCK, len(idx))
            while k < end:
                if ok[k]:
                    j = k + int(np.argmin(ok[k:end])) if not ok[k:end].all() else end
                    out[idx[k:j]] = self._run_many(x[k - a : j - a], dt[k:j])
                    self._t[0], self._y[0] = t[j - 1], out[idx[j - 1]]
                    k = j
                else:
                    out[idx[k]] = self.step(x[k - a], t[k])
                    k += 1
        return anim.with_values(out)

    def _run_many(self, xs: np.ndarray, dts: np.ndarray) -> np.ndarray:
        """One stream advanced over frames xs (N, M) by dts (N,) s: outputs (N, M)."""
        ws, out = self._ws, np.empty_like(xs)
        if self.kernel == "numba":
            jit.run(*ws.jit_args, xs, dts, out)
            return out
        for n in range(len(xs)):
            ws.dt[0, 0] = dts[n]
            np.copyto(ws.x[:, 0], xs[n], casting="unsafe")
            step_numpy(ws, self._wts, self._head_t, self.lo, self.hi, self._mode)
            out[n] = ws.y[:, 0]
        return out


def _sane(flat: np.ndarray) -> bool:
    """Every value finite and within +-MAX_ABS (NaN fails both comparisons); two
    reductions, no allocation and no overflow warning, for the per-frame fast path."""
    return bool(flat.max() <= MAX_ABS) and bool(flat.min() >= -MAX_ABS)
