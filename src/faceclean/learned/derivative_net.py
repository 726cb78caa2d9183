"""The paper's non-recurrent baselines (SPEC section 3): FC and GBT, numpy runtime.

Both predict the K = 4 time-derivatives of the clean signal from the input alone, then
integrate them with the complementary blend, for k = 0..K-1 with X̂^(0) = X_i:

    X_r^(k)[n+1] = α (X_r^(k)[n] + dt X̂^(k+1)) + (1 − α) X̂^(k)[n+1],   X_r^(0) = output.

Indices, the causal reading (SPEC section 2, step 2): when input frame n+1 arrives,
every derivative is a backward difference ending at its frame,
d^(k)[n+1] = (d^(k-1)[n+1] − d^(k-1)[n]) / dt, d^(0) = x_i. The features are the current
input and the input's K derivatives ending at n+1 and at n, per channel
``[x, d^(1..K)[n+1], d^(1..K)[n]]`` (1 + 2K values); the model predicts the truth's
backward derivatives at n+1 (the slope from n to n+1 for k = 1, the SPEC's forward
X̂^(k+1)[n]). With the SPEC's form only X̂^(1) reaches the output; X_r^(1..K-1) are
the smoothed derivative estimates, kept as state.

α: the paper's per-frame α_r (0.9 FC, 0.97 GBT) was chosen at its 60 fps test rate; it is
applied as α = α_r^(dt · 60 Hz), the same blend time constant at every rate
(τ = −1 / (60 ln α_r): 0.16 s FC, 0.55 s GBT) and exactly the paper's at 60 fps.
``per_frame=True`` gives the literal per-frame form (its smoothing then depends on fps).

Checkpoints are npz (``allow_pickle=False``) written by ``faceclean.neural.baselines``:
``config`` (JSON: format, channels, K, alpha, value_range, val_sources, ...) plus
- FC (``faceclean-fc/1``), a whole-face MLP: ``feat_mean``, ``feat_std`` (F·M,) over
  the feature-major vector ``[x (M), d^(1)[n+1] (M) .. d^(K)[n] (M)]``, the scaled
  features clipped to +-``config["feat_clip"]`` (outliers: spikes, drops); ``fc.{l}.w``
  (out, in), ``fc.{l}.b``, ReLU between layers; output (K·M,) order-major, times
  ``out_std`` plus ``out_mean``.
- GBT (``faceclean-gbt/1``), trees shared by all channels, one ensemble per order, on
  raw per-channel features plus the channel's group index, as T complete binary trees
  of depth D in implicit layout (children of node i: 2i+1, 2i+2): ``tree.feature`` and
  ``tree.threshold`` (T, 2^D - 1) (go left when ``x <= threshold``), ``tree.value``
  (T, 2^D) leaves, ``tree.order`` (T,) the order each tree predicts; ``baseline`` (K,)
  and ``out_std`` (K,): order k is ``out_std[k] * (baseline[k] + Σ value[leaf])``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from faceclean.animation import Animation
from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52, GROUPS, channel_key
from faceclean.errors import FacecleanError
from faceclean.filters.base import MAX_ABS, State, StreamCleaner
from faceclean.learned import formats
from faceclean.learned.checkpoint import read_config

GROUP_NAMES = tuple(GROUPS)
ALPHA_RATE = 60.0  # Hz; α_r is the paper's per-frame value at its 60 fps test rate
BIG = 1e30  # derivatives are clipped to +-BIG (a dt of 1e-9 s must not overflow)


def load_checkpoint(path: str | os.PathLike, fmt: str) -> tuple[dict[str, Any], dict]:
    """(config, arrays) of a baseline checkpoint; FacecleanError if it is not one."""
    arrays = formats.read_arrays(path)
    config = read_config(arrays, Path(path).name, fmt)  # checked: one line, never later
    arrays.pop("config")
    for key, a in arrays.items():
        if a.dtype.kind not in "iuf":  # tree thresholds may be +-inf: only the kind is checked
            raise FacecleanError(f"{Path(path).name}: {key} is not an array of real numbers")
    return config, arrays


def blend(r: np.ndarray, d_hat: np.ndarray, x: np.ndarray, dt, alpha) -> np.ndarray:
    """One complementary-blend step, every order at once. r: X_r^(0..K-1)[n] (..., K, M);
    d_hat: X̂^(1..K) (..., K, M); x: X_i[n+1] (..., M); dt, alpha: scalars or (..., 1, 1).

    Returns X_r^(0..K-1)[n+1] (..., K, M). α = 0 follows the prediction (the input for
    k = 0); α = 1 with zero derivatives holds.
    """
    below = np.concatenate([x[..., None, :], d_hat[..., :-1, :]], axis=-2)  # X̂^(0..K-1)
    return alpha * (r + dt * d_hat) + (1.0 - alpha) * below


def group_index(names: Sequence[str]) -> np.ndarray:
    """(M,) float: each channel's group in GROUPS order (len(GROUPS) when unknown)."""
    out = []
    for n in names:
        c = channel_key(n)
        out.append(next((i for i, g in enumerate(GROUPS.values()) if c in g), len(GROUPS)))
    return np.asarray(out, np.float64)


class _DerivativeNet(StreamCleaner):
    """Shared runtime: derivative features, a model (``_predict``), the blend."""

    fmt: ClassVar[str] = ""
    default_file: ClassVar[str] = ""
    batched: ClassVar[bool] = False  # clean() predicts all frames at once (bit-exact models)

    def __init__(
        self,
        *,
        model: str | os.PathLike | None = None,
        alpha: float | None = None,
        per_frame: bool = False,
        names: Sequence[str] = ARKIT52,
    ) -> None:
        from faceclean.settings import MODELS

        path = model if model is not None else MODELS / self.default_file
        config, arrays = load_checkpoint(path, self.fmt)
        self._load(arrays)
        self._setup(config, names, alpha, per_frame)

    def _setup(
        self, config: dict, names: Sequence[str], alpha: float | None, per_frame: bool = False
    ) -> None:
        self.config = config
        self.channels = tuple(config["channels"])  # model channels (M,)
        self.K = int(config["K"])
        self.alpha = float(config["alpha"] if alpha is None else alpha)
        if not 0.0 <= self.alpha <= 1.0:
            raise FacecleanError(f"{self.name}: alpha must be in [0, 1], got {self.alpha}")
        self.per_frame = bool(per_frame)
        self.lo, self.hi = (float(v) for v in config.get("value_range", [0.0, 1.0]))
        # frame column of each model channel (-1: the frame lacks it; it sees zeros)
        self._cols = ChannelMap(self.channels, names).src
        self._have = self._cols >= 0
        self._dst = self._cols[self._have]  # frame columns the output writes
        # the frame is the model's channels in its order: no gather, no scatter
        self._same = len(names) == len(self.channels) and bool(
            (self._cols == np.arange(len(self.channels))).all()
        )
        self._pending: list[np.ndarray] | None = None  # batch path: precomputed predictions
        self._record: list[np.ndarray] | None = None  # batch path: recorded features
        self._ages: list[np.ndarray] = []  # advances since the start, per recorded step
        self.reset()

    def _load(self, arrays: dict) -> None:
        raise NotImplementedError

    def predict(self, feats: np.ndarray) -> np.ndarray:
        """Derivative predictions (n, M, K) from features (n, M, 1 + 2K)."""
        raise NotImplementedError

    def _predict_fm(self, f: np.ndarray) -> np.ndarray:
        """``predict`` on the feature-major layout: (S, 1 + 2K, M) -> (S, K, M)."""
        return self.predict(f.transpose(0, 2, 1)).transpose(0, 2, 1)

    def _model_frame(self, x: np.ndarray) -> np.ndarray:
        """(S, M_in) frame -> (S, M) model channels (zeros where absent)."""
        if self._same:
            return x
        return np.where(self._have, x[:, np.maximum(self._cols, 0)], 0.0)

    # State, per stream: f (S, 1 + 2K, M) the features of the last step, feature-major
    # [d^(0..K)[n], d^(1..K)[n-1]]; r (S, K, M) X_r^(0..K-1)[n]; age (S, M) advances since
    # the start. f's first K + 1 rows are what the next step differences against.
    def _start(self, x: np.ndarray) -> State:
        xm = self._model_frame(x)
        f = np.zeros((len(xm), 1 + 2 * self.K, xm.shape[1]))
        r = np.zeros((len(xm), self.K, xm.shape[1]))
        f[:, 0] = r[:, 0] = xm
        return f, r, np.zeros_like(xm)

    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        K = self.K
        f_old, r_old, age = state
        f = np.empty_like(f_old)
        f[:, 0] = self._model_frame(x)
        f[:, K + 1 :] = f_old[:, 1 : K + 1]  # d^(1..K) ending at the previous frame
        for k in range(1, K + 1):  # backward differences ending at the new frame
            d = np.subtract(f[:, k - 1], f_old[:, k - 1], out=f[:, k])
            _clip(np.divide(d, dt, out=d), -BIG, BIG)  # finite inputs: at worst +-inf
        if self._record is not None:
            self._record.append(f.transpose(0, 2, 1))  # (S, M, 1 + 2K)
            self._ages.append(age.copy())
            pred = np.zeros((len(f), K, f.shape[2]))
        elif self._pending is not None:
            pred = self._pending.pop().transpose(0, 2, 1)
        else:
            pred = self._predict_fm(f)  # (S, K, M)
        # α per frame at ALPHA_RATE, as a time constant: the same blend at every rate.
        alpha = self.alpha if self.per_frame else self.alpha ** (dt * ALPHA_RATE)  # (S, 1)
        dt3 = dt[:, :, None]
        r_new = blend(r_old, pred, f[:, 0], dt3, alpha if self.per_frame else alpha[:, :, None])
        out = _clip(r_new[:, 0], self.lo, self.hi)  # a view: r_new's X_r^(0) clipped too
        if self._same:
            y = out.copy()
        else:
            y = x.copy()
            y[:, self._dst] = out[:, self._have]
        return (f, r_new, age + 1.0), y

    def features(self, anim: Animation) -> tuple[np.ndarray, np.ndarray]:
        """Features of every advancing step: ((n, M, 1 + 2K), ages (n, M)).

        ``ages`` counts the advances before the step since the last start; a step's
        derivatives are complete when its age is at least K.
        """
        try:
            self._record, self._ages = [], []
            super().clean(anim)
            m, f = len(self.channels), 1 + 2 * self.K
            if not self._record:
                return np.zeros((0, m, f)), np.zeros((0, m))
            return np.concatenate(self._record), np.concatenate(self._ages)
        finally:
            self._record, self._ages = None, []

    def clean(self, anim: Animation) -> Animation:
        """Reset-then-step, with the model run once on every frame's features (batched).

        The features depend on the input only, so a first pass records them, one batched
        prediction follows, and a second pass blends: the same numbers as stepping when the
        model is exact row by row (trees; a matrix product is not, so FC steps). A lost or
        absurd value in a kept frame takes the last output (filters.base rule 2), which the
        first pass does not know: such clips step.
        """
        if not self.batched or _fills(anim.values):
            return super().clean(anim)
        try:
            self._record = []
            super().clean(anim)
            recorded, self._record, self._ages = self._record, None, []
            if recorded:
                shapes = [f.shape[0] for f in recorded]
                pred = self.predict(np.concatenate(recorded))
                self._pending = np.split(pred, np.cumsum(shapes)[:-1])[::-1]
            return super().clean(anim)
        finally:
            self._record = self._pending = None
            self._ages = []


def _clip(a: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``np.clip(a, lo, hi, out=a)`` as two ufuncs, the same numbers (NaN stays NaN):
    np.clip's Python wrapper costs more than the clipping on one stream's (1, M)."""
    return np.minimum(np.maximum(a, lo, out=a), hi, out=a)


def _fills(values: np.ndarray) -> bool:
    """Whether rule 2 (filters.base) fills a value of (N, M) ``values`` from the output:
    a non-finite or absurd value in a frame that has a good one."""
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(values) <= MAX_ABS)
    return bool((bad.any(axis=1) & ~bad.all(axis=1)).any())


class FullyConnected(_DerivativeNet):
    """FC baseline (method "fc"): whole-face MLP on the 52 channels' features, α = 0.9."""

    name = "fc"
    fmt = formats.FC
    default_file = "fc.npz"
    jit_min_streams: int = 2  # compiled features and blend from here (docs/BENCHMARKS.md)

    def _load(self, a: dict) -> None:
        n = len([k for k in a if k.startswith("fc.") and k.endswith(".w")])
        # float32 layers, as trained and stored: half the bytes a step reads (the
        # products are memory-bound for one stream); features and output stay float64
        self._w = [np.ascontiguousarray(a[f"fc.{i}.w"].astype(np.float32).T) for i in range(n)]
        self._b = [a[f"fc.{i}.b"].astype(np.float32) for i in range(n)]
        fm, fs = a["feat_mean"].astype(np.float64), a["feat_std"].astype(np.float64)
        self._om, self._os = a["out_mean"].astype(np.float64), a["out_std"].astype(np.float64)
        # The scaling folded into layer 0 (one pass over the features, not three):
        #   clip((f - fm) / fs, -c, c) W0 = clip(f, fm - c fs, fm + c fs) (W0 / fs) - (fm / fs) W0
        self._feat_scaling = (fm, fs)  # as stored (the float64 reference of the tests)
        w0 = self._w[0].astype(np.float64)  # (F M, H)
        self._w0 = np.ascontiguousarray(w0 / fs[:, None]).astype(np.float32)
        self._b0 = (self._b[0] - (fm / fs) @ w0).astype(np.float32)
        self._jit: bool | None = None  # numba for many streams: unknown until then

    def _setup(self, config: dict, names, alpha, per_frame: bool = False) -> None:
        (fm, fs), c = self._feat_scaling, float(config.get("feat_clip", np.inf))
        self._lo, self._hi = (fm - c * fs).astype(np.float32), (fm + c * fs).astype(np.float32)
        super()._setup(config, names, alpha, per_frame)

    def predict(self, feats: np.ndarray) -> np.ndarray:
        n, m, f = feats.shape
        x = feats.transpose(0, 2, 1).reshape(n, f * m)  # feature-major: a view from _advance
        h = np.maximum(x, self._lo, out=np.empty((n, f * m), np.float32), casting="same_kind")
        np.minimum(h, self._hi, out=h)  # raw features kept where their scaled form is +-clip
        for i, (w, b) in enumerate(zip((self._w0, *self._w[1:]), (self._b0, *self._b[1:]),
                                       strict=True)):  # fmt: skip
            h = h @ w  # w (in, out)
            h += b
            if i < len(self._w) - 1:
                np.maximum(h, 0.0, out=h)
        out = h.astype(np.float64) * self._os + self._om  # (n, K·M) order-major
        return out.reshape(n, self.K, m).transpose(0, 2, 1)

    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        """From ``jit_min_streams`` streams on, with numba: the features and the blend
        compiled (learned/jit.py ``fc_features``, ``fc_blend``: one pass each instead of
        some 30 numpy calls over arrays out of cache), the products numpy's; the same
        bits as the numpy step (tests/learned/test_bench_rows.py). One stream, and so
        ``clean``, stays numpy: no numba load (~1.8 s) for a take."""
        if len(x) < self.jit_min_streams or self._record is not None or not self._jit_ready():
            return super()._advance(state, x, dt)
        from faceclean.learned import jit

        f_old, r_old, age = state
        f = np.empty_like(f_old)
        h = np.empty((len(f), f.shape[1] * f.shape[2]), np.float32)
        jit.fc_features(f_old, self._model_frame(x), dt, BIG, self._lo, self._hi, f, h)
        weights, biases = (self._w0, *self._w[1:]), (self._b0, *self._b[1:])
        for w, b in zip(weights[:-1], biases[:-1], strict=True):  # ``predict``'s layers
            h = h @ w
            h += b
            np.maximum(h, 0.0, out=h)
        h = h @ weights[-1]  # its bias is added in fc_blend
        if self.per_frame:
            alpha = np.full(len(f), self.alpha)
        else:  # (S,), as ``_DerivativeNet._advance``
            alpha = self.alpha ** (dt[:, 0] * ALPHA_RATE)
        r_new = np.empty_like(r_old)
        jit.fc_blend(h, biases[-1], self._os, self._om, f, r_old, dt, alpha, self.lo, self.hi,
                     r_new)  # fmt: skip
        if self._same:
            y = r_new[:, 0].copy()
        else:
            y = x.copy()
            y[:, self._dst] = r_new[:, 0, self._have]
        return (f, r_new, age + 1.0), y

    def _jit_ready(self) -> bool:
        if self._jit is None:  # loaded at the first step of many streams
            from faceclean.learned import jit

            self._jit = jit.available()
        return self._jit


class BoostedTrees(_DerivativeNet):
    """GBT baseline (method "gbt"): per-channel trees shared by all channels, α = 0.97."""

    name = "gbt"
    fmt = formats.GBT
    default_file = "gbt.npz"
    batched = True

    def _load(self, a: dict) -> None:
        # trees grouped by the order they predict (a stable sort: each order's sum adds
        # its trees in the stored order), so an order's leaves are one slice
        by = np.argsort(a["tree.order"].astype(np.intp), kind="stable")
        self._feat = a["tree.feature"].astype(np.intp)[by]  # (T, 2^D - 1)
        self._thr = a["tree.threshold"].astype(np.float64)[by]  # (T, 2^D - 1)
        self._val = a["tree.value"].astype(np.float64)[by]  # (T, 2^D)
        self._order = a["tree.order"].astype(np.intp)[by]  # (T,)
        self._base = a["baseline"].astype(np.float64)  # (K,)
        self._ostd = a["out_std"].astype(np.float64)  # (K,)
        t, n_in = self._feat.shape
        self._depth = int(np.log2(n_in + 1))
        # flat node index i = tree * n_in + node; a step down: node -> 2 node + 1 + right,
        # i.e. i -> 2 i + 1 + right - tree * n_in; the leaf at node p of tree is value
        # [tree, p - n_in], flat tree * (n_in + 1) + p - n_in = i + tree - n_in
        self._in_off = np.arange(t) * n_in  # (T,) first internal node of each tree
        self._leaf_off = np.arange(t) * (n_in + 1) - n_in  # leaf position -> flat index
        self._down = 1 - self._in_off  # (T,)
        self._to_leaf = np.arange(t) - n_in  # (T,)
        self._feat_flat, self._thr_flat = self._feat.ravel(), self._thr.ravel()
        self._val_flat = self._val.ravel()
        self._groups: np.ndarray | None = None
        self._jit = None  # the compiled trees (learned/jit.py), False without numba
        ends = np.searchsorted(self._order, np.arange(len(self._base) + 1))
        self._slices = [slice(a, b) for a, b in zip(ends[:-1], ends[1:], strict=True)]

    def predict(self, feats: np.ndarray) -> np.ndarray:
        n, m, _ = feats.shape
        if self._groups is None:
            self._groups = group_index(self.channels)
        x = np.concatenate([feats, np.broadcast_to(self._groups[None, :, None], (n, m, 1))], -1)
        x = x.reshape(n * m, -1)
        out = np.empty((n * m, self.K))
        step = max(1, 400_000 // len(self._order))  # samples per chunk: bounded memory
        for s in range(0, n * m, step):
            out[s : s + step] = self.predict_features(x[s : s + step])
        return out.reshape(n, m, self.K)

    def predict_features(self, x: np.ndarray) -> np.ndarray:
        """(n, K) predictions from (n, F) raw per-channel features (last one: group)."""
        n, f = x.shape
        xf, row = x.ravel(), (np.arange(n) * f)[:, None]  # x[i, j] = xf[i f + j]
        at = np.broadcast_to(self._in_off, (n, len(self._order)))  # (n, T) flat node
        for _ in range(self._depth):  # every tree descends one level per pass
            right = xf.take(row + self._feat_flat.take(at)) > self._thr_flat.take(at)
            at = 2 * at + self._down + right  # left when x <= thr
        leaf = self._val_flat.take(at + self._to_leaf)  # (n, T)
        out = np.empty((len(x), self.K))
        for k, trees in enumerate(self._slices):  # tree after tree (learned/jit.py's order)
            out[:, k] = np.cumsum(leaf[:, trees], axis=1)[:, -1] if len(leaf) else 0.0
        return (out + self._base) * self._ostd

    def _predict_fm(self, f: np.ndarray) -> np.ndarray:
        """A step's predictions (S, K, M): learned/jit.py's compiled trees when numba is
        installed (loaded at the first step: ``clean`` predicts batched, in numpy), the
        same numbers as numpy's."""
        if self._jit is None:
            from faceclean.learned import jit

            self._jit = jit.trees if jit.available() else False
        if not self._jit:
            return super()._predict_fm(f)
        if self._groups is None:
            self._groups = group_index(self.channels)
        out = np.zeros((len(f), self.K, f.shape[2]))
        self._jit(f, self._groups, self._feat, self._thr, self._val, self._order, self._depth, out)
        return (out + self._base[:, None]) * self._ostd[:, None]


class DerivativeFeatures(_DerivativeNet):
    """The FC/GBT feature pass without a model (training data): ``features(anim)``."""

    name = "derivative-features"

    def __init__(self, *, K: int = 4, names: Sequence[str] = ARKIT52) -> None:
        config = {"channels": list(names), "K": K, "alpha": 0.0, "value_range": [-np.inf, np.inf]}
        self._setup(config, names, None)
