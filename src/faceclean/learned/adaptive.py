"""The learned adaptive filter: a One Euro filter whose cut-off a small recurrent core sets.

Why this shape (issue 11): a cleaner must not become a *pose prior*. The output is
always a step from the last output toward the newest input, so a held pose converges
exactly to where the tracker puts it and no resting level can move; the network only
decides *how fast* to follow, per channel and per frame. Its zero network is the tuned
One Euro filter, so training starts from a good filter, not from the raw input.

One step, per stream and channel c, input x (M,) arriving dt s after the last frame,
state (y, edx, h, s):

    e     = x - y                                   innovation, weight units
    edx   = edx + alpha(d_cutoff, dt) (e / dt - edx) One Euro's slope, weight/s
    f_c   = [e/E0, clip(edx/V0, ±4), |e|/E0, mean_{group(c)} |e|/E0, mean_all |e|/E0,
             e_{mirror(c)}/E0, log(60 dt)] (clipped to ±F_MAX) ++ emb[c]      (7 + E,)
    h_c   = GRUCell(f_c, h_c)                       the same weights for every channel
    a, b  = head(h_c)
    fc    = (min_cutoff_c + beta_c |edx|) exp(clip(a, A_MIN, A_MAX))             Hz
    p     = y + sigmoid(b) dt edx                   a learned share of the slope (lag)
    y'    = p + alpha(fc, dt) (x - p),  clamped to [min(0, x), max(1, x)]   the state
    s'    = s + alpha(F_SLOW, dt) (y' - s)          the slow level of y', F_SLOW Hz
    out   = y' + G_MAX tanh(boost_c) (y' - s'),  clamped the same way

The last line is a learned, per-channel constant gain on the *transient* y' - s' only
(blinks a tracker under-reads): it vanishes on a held pose (s' -> y' -> x), and being
constant in time it averages to zero over a take, so it cannot move a resting level
either (a gain the core set per frame did: it moved browInnerUp by 0.006 on clean takes).

with alpha(fc, dt) = 1 / (1 + 1 / (2 pi fc dt)), the first-order low-pass of One Euro:
time constants in seconds, so the same filter at any frame rate. The time rules
(missing frames, NaN cells, gaps, backwards time) are filters/base.py's.

An inert network costs nothing (issue 19): when ``head.w`` is all zero, (a, b) are the
head's bias whatever h is, so the GRU cannot change the result; the model is detected at
load (``Adaptive.inert``) and stepped without the core, as One Euro with the constant
cut-off factor exp(a) and slope share sigmoid(b) (bitwise the same numbers). With
``boost`` also zero the transient gain is zero and the slow level is not kept either.
The shipped default is such a model: the tuned One Euro filter in this form.

One Euro's own keys set the filter under the core: ``min_cutoff``, ``beta``, ``d_cutoff``
(Hz, Hz per weight/s, Hz; for every channel or (M,) per channel) replace the model's.

Checkpoint (.npz, no pickle): ``config`` JSON {"format": FORMAT, "channels": [M],
"hidden": H, "embed": E, ...training facts}; arrays ``emb`` (M, E), ``gru.w_ih``
(3H, 7+E), ``gru.w_hh`` (3H, H), ``gru.b_ih``, ``gru.b_hh`` (3H,) in PyTorch's (r, z, n)
gate order, ``head.w`` (2, H), ``head.b`` (2,), ``boost`` (M,), ``min_cutoff``, ``beta``,
``d_cutoff`` (M,) in Hz and Hz per (weight/s).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from faceclean import strict_json
from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52, group_of
from faceclean.errors import FacecleanError
from faceclean.filters.base import MAX_GAP, State, StreamCleaner, gap_seconds
from faceclean.filters.params import per_channel
from faceclean.learned import formats
from faceclean.learned.formats import ADAPTIVE as FORMAT

N_FEATURES = 7  # per-channel signal features before the embedding
E0 = 0.05  # weight units: the innovation scale the features are measured in
V0 = 5.0  # weight/s: the slope scale
F_MAX = 10.0  # features are clipped to +-F_MAX (a glitch must not saturate the core)
# The cut-off may open up to e^1.5 = 4.5x One Euro's (follow a fast move, or a take that
# needs no cleaning) but close only to e^-0.5 = 0.6x: smoothing much more than the tuned
# filter was what made a learned cut-off worse than raw on held-out takes whose clean
# truth itself jitters (sentien, jmtechart; docs/MODEL.md).
A_MIN, A_MAX = -0.5, 1.5
F_SLOW = 0.5  # Hz: the slow level the transient gain is measured from (tau 0.32 s)
G_MAX = 1.0  # the transient gain lies in (-G_MAX, G_MAX)
DT_MIN = 1e-4  # s; a smaller step is taken as this one

# ARKit-52 mirror partner (left <-> right), and each channel's group, by canonical name.
_SIDES = (("Left", "Right"), ("Right", "Left"))


def mirror_index(names: Sequence[str]) -> np.ndarray:
    """(M,) index of each channel's other side (itself when it has none)."""
    where = {n: i for i, n in enumerate(names)}
    out = np.arange(len(names))
    for i, n in enumerate(names):
        for a, b in _SIDES:
            if n.endswith(a) and n[: -len(a)] + b in where:
                out[i] = where[n[: -len(a)] + b]
    return out


def group_matrix(names: Sequence[str]) -> np.ndarray:
    """(M, M) averaging matrix: row c is 1/|g| on the channels of c's group g."""
    groups = [group_of(n) or n for n in names]
    same = np.array([[a == b for b in groups] for a in groups], dtype=np.float64)
    return same / same.sum(1, keepdims=True)


def is_adaptive(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a readable .npz whose config names this format."""
    try:
        raw = formats.read_arrays(path)["config"]
        config = strict_json.loads(str(raw[()]), "config")
    except (FacecleanError, KeyError, ValueError, TypeError, IndexError):
        return False
    return isinstance(config, dict) and config.get("format") == FORMAT


MAX_WIDTH = 4096  # the widest hidden state or channel embedding a config may name


def alpha(cutoff: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Smoothing factor of a first-order low-pass at ``cutoff`` Hz for a step of dt s."""
    return 1.0 / (1.0 + 1.0 / (2.0 * np.pi * cutoff * dt))


def sigmoid(a: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * a))


@dataclass(frozen=True)
class AdaptiveWeights:
    """A checkpoint's config and arrays (float64 for the runtime), validated."""

    config: dict[str, Any]
    arrays: dict[str, np.ndarray]

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.config["channels"])

    @property
    def hidden(self) -> int:
        return int(self.config["hidden"])

    @classmethod
    def load(cls, path: str | os.PathLike) -> AdaptiveWeights:
        """Read and check a ``faceclean-adaptive/1`` .npz; FacecleanError if it is not one."""
        p = Path(path)
        arrays = formats.read_arrays(p)
        try:
            raw = str(arrays.pop("config")[()])
        except (KeyError, ValueError, TypeError, IndexError):
            raise FacecleanError(f"{p.name}: not a faceclean model (no readable config)") from None
        config = strict_json.loads(raw, f"{p.name}: config")
        return cls.from_arrays(config, arrays, p.name)

    @classmethod
    def from_arrays(
        cls, config: dict[str, Any], arrays: dict[str, np.ndarray], what: str = "model"
    ) -> AdaptiveWeights:
        if not isinstance(config, dict) or config.get("format") != FORMAT:
            raise FacecleanError(f"{what}: not a {FORMAT} model")
        names = config.get("channels")
        if (
            not isinstance(names, list)
            or not names
            or not all(isinstance(n, str) and n for n in names)
            or len(set(names)) != len(names)
        ):
            raise FacecleanError(f"{what}: config channels must be a list of distinct names")
        for key in ("hidden", "embed"):
            v = config.get(key)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= MAX_WIDTH:
                raise FacecleanError(
                    f"{what}: config {key} must be a whole number in [1, {MAX_WIDTH}] (got {v!r})"
                )
        H, E = config["hidden"], config["embed"]
        M, F = len(names), N_FEATURES + E
        shapes = {
            "emb": (M, E), "gru.w_ih": (3 * H, F), "gru.w_hh": (3 * H, H),
            "gru.b_ih": (3 * H,), "gru.b_hh": (3 * H,), "head.w": (2, H), "head.b": (2,),
            "boost": (M,),
            "min_cutoff": (M,), "beta": (M,), "d_cutoff": (M,),
        }  # fmt: skip
        out = {}
        for key, shape in shapes.items():
            a = arrays.get(key)
            if a is None or a.shape != shape or a.dtype.kind != "f":
                raise FacecleanError(f"{what}: array {key} missing or not float {shape}")
            a = a.astype(np.float64)
            if not np.isfinite(a).all():
                raise FacecleanError(f"{what}: array {key} has non-finite values")
            out[key] = a
        for key in ("min_cutoff", "d_cutoff"):
            if (out[key] <= 0).any():
                raise FacecleanError(f"{what}: {key} must be > 0 Hz")
        if (out["beta"] < 0).any():
            raise FacecleanError(f"{what}: beta must be >= 0")
        return cls({**config, "channels": names}, out)

    def save(self, path: str | os.PathLike) -> None:
        """Write the checkpoint (float32 arrays, JSON config) atomically."""
        from faceclean.io.atomic import atomic_open

        arrays = {k: v.astype(np.float32) for k, v in self.arrays.items()}
        with atomic_open(path, "wb") as f:
            np.savez(f, config=np.array(json.dumps(self.config)), **arrays)


class Adaptive(StreamCleaner):
    """The learned adaptive filter (module docstring) on M channels, S streams at once.

    ``names``: the stream's channels. Model channels are matched by canonical name;
    stream channels the model does not know pass through a plain One Euro step at the
    model's mean cut-off (a zero network), never untouched and never invented.
    """

    name = "adaptive"
    PER_CHANNEL = ("min_cutoff", "beta", "d_cutoff")  # One Euro's keys, over the model's

    def __init__(
        self,
        model: str | os.PathLike | None = None,
        *,
        names: Sequence[str] = ARKIT52,
        weights: AdaptiveWeights | None = None,
        max_gap: float = MAX_GAP,
        min_cutoff: float | Sequence[float] | None = None,
        beta: float | Sequence[float] | None = None,
        d_cutoff: float | Sequence[float] | None = None,
    ) -> None:
        if weights is None:
            if model is None:
                from faceclean.settings import MODELS

                model = MODELS / "default.npz"
            weights = AdaptiveWeights.load(model)
        self.weights = weights
        self.names = tuple(names)
        self.max_gap = gap_seconds(max_gap)
        w = weights.arrays
        rows = ChannelMap(self.names, weights.channels).src
        self._learn = rows >= 0  # (M,) channels the model knows
        mean = {k: float(np.exp(np.log(w[k]).mean())) for k in ("min_cutoff", "d_cutoff")}
        mean["beta"] = float(w["beta"].mean())
        pick = np.maximum(rows, 0)
        given = {"min_cutoff": min_cutoff, "beta": beta, "d_cutoff": d_cutoff}
        for key, value in given.items():
            own = np.where(self._learn, w[key][pick], mean[key])  # (M,) the model's
            if value is not None:  # One Euro's key given: it replaces the model's
                v = per_channel(value, self.names, f"adaptive {key}", open_low=key != "beta")
                own = np.broadcast_to(v, own.shape).astype(np.float64)
            setattr(self, key, own)  # (M,)
        self._emb = np.where(self._learn[:, None], w["emb"][pick], 0.0)  # (M, E)
        self._gain = np.where(self._learn, G_MAX * np.tanh(w["boost"][pick]), 0.0)  # (M,)
        self._mirror = mirror_index(self.names)
        self._group = group_matrix(self.names)
        self._H = weights.hidden
        self._w_ih, self._w_hh = w["gru.w_ih"].T, w["gru.w_hh"].T  # (F, 3H), (H, 3H)
        # The embedding's share of the input product is the same every step: (M, 3H).
        self._emb_gates = self._emb @ self._w_ih[N_FEATURES:] + w["gru.b_ih"]
        self._b_hh, self._head_w, self._head_b = w["gru.b_hh"], w["head.w"].T, w["head.b"]
        # Inert network: a head blind to h makes (a, b) constants, the core dead weight.
        self.inert = not np.any(w["head.w"])
        self._transient = bool(np.any(self._gain))  # a zero gain needs no slow level
        b = w["head.b"]
        self._ea = np.where(self._learn, np.exp(np.clip(b[0], A_MIN, A_MAX)), 1.0)  # (M,)
        self._k = np.where(self._learn, sigmoid(b[1]), 0.0)  # (M,)
        self._w_d = 2.0 * np.pi * self.d_cutoff  # (M,) rad/s
        # numpy, not numba: a compiled inert step saved ~30 us a frame but cost ~1.8 s to
        # load in every process (numba's start-up), 30x what it saves on a 2,000-frame take
        self.reset()

    def _start(self, x: np.ndarray) -> State:
        s, m = x.shape
        if self.inert:  # no core state; the slow level only where a transient gain needs it
            return (x.copy(), np.zeros_like(x)) + ((x.copy(),) if self._transient else ())
        return x.copy(), np.zeros_like(x), np.zeros((s, m * self._H)), x.copy()

    def _compiled(self):
        if not self.inert or self._transient:
            return None
        from faceclean.filters import compiled

        m = len(self.names)
        return compiled.inert(m, self.min_cutoff, self.beta, self._w_d, self._ea, self._k)

    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        if self.inert:
            return self._advance_inert(state, x, dt)
        y, edx, h, slow = state  # (S, M), (S, M) weight/s, (S, M*H), (S, M)
        s, m = x.shape
        H = self._H
        dt = np.maximum(dt, DT_MIN)  # (S, 1) s
        e = x - y
        edx = edx + alpha(self.d_cutoff, dt) * (e / dt - edx)
        en = e / E0
        f = np.stack(
            [
                en,
                np.clip(edx / V0, -4.0, 4.0),
                np.abs(en),
                np.abs(en) @ self._group.T,
                np.broadcast_to(np.abs(en).mean(1, keepdims=True), (s, m)),
                en[:, self._mirror],
                np.broadcast_to(np.log(60.0 * dt), (s, m)),
            ],
            axis=-1,
        )  # (S, M, 7)
        f = np.clip(f, -F_MAX, F_MAX)
        h = h.reshape(s, m, H)
        gi = f @ self._w_ih[:N_FEATURES] + self._emb_gates  # (S, M, 3H)
        gh = h @ self._w_hh + self._b_hh
        r = sigmoid(gi[..., :H] + gh[..., :H])
        z = sigmoid(gi[..., H : 2 * H] + gh[..., H : 2 * H])
        n = np.tanh(gi[..., 2 * H :] + r * gh[..., 2 * H :])
        h = (1.0 - z) * n + z * h
        out = h @ self._head_w + self._head_b  # (S, M, 2)
        a = np.where(self._learn, np.clip(out[..., 0], A_MIN, A_MAX), 0.0)
        k = np.where(self._learn, sigmoid(out[..., 1]), 0.0)
        fc = (self.min_cutoff + self.beta * np.abs(edx)) * np.exp(a)
        p = y + k * dt * edx
        y = p + alpha(fc, dt) * (x - p)
        lo, hi = np.minimum(x, 0.0), np.maximum(x, 1.0)
        y = np.clip(y, lo, hi)
        slow = slow + alpha(F_SLOW, dt) * (y - slow)
        shown = np.clip(y + self._gain * (y - slow), lo, hi)
        return (y, edx, h.reshape(s, m * H), slow), shown

    def _advance_inert(
        self, state: State, x: np.ndarray, dt: np.ndarray
    ) -> tuple[State, np.ndarray]:
        """The step above with a = a0, k = sigmoid(b0) constants (M,): no core, the same
        numbers (the same operations in the same order on every value that matters)."""
        y, edx = state[0], state[1]  # (S, M) weight, (S, M) weight/s
        dt = np.maximum(dt, DT_MIN)  # (S, 1) s
        # alpha(d_cutoff, dt) with 2 pi d_cutoff folded (the same product, rounded alike)
        a_d = 1.0 / (1.0 + 1.0 / (self._w_d * dt))
        edx = edx + a_d * ((x - y) / dt - edx)
        fc = (self.min_cutoff + self.beta * np.abs(edx)) * self._ea  # Hz
        p = y + self._k * dt * edx
        y = p + alpha(fc, dt) * (x - p)
        # clip to [min(0, x), max(1, x)]: np.clip's wrapper costs more than these two
        y = np.minimum(np.maximum(y, np.minimum(x, 0.0)), np.maximum(x, 1.0))
        if not self._transient:
            return (y, edx), y
        lo, hi = np.minimum(x, 0.0), np.maximum(x, 1.0)
        slow = state[2] + alpha(F_SLOW, dt) * (y - state[2])
        return (y, edx, slow), np.clip(y + self._gain * (y - slow), lo, hi)

    @property
    def state_bytes(self) -> int:
        """Bytes of state per stream: y, edx, the slow level and the core's hidden state
        (an inert model keeps y and edx, and the slow level only with a transient gain)."""
        if self.inert:
            return 8 * len(self.names) * (2 + self._transient)
        return 8 * len(self.names) * (3 + self._H)
