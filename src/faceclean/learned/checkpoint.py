"""The learned model's checkpoint (docs/ARCHITECTURE.md), read without torch.

``LSTMWeights.load(path)`` checks and holds the raw arrays; ``fused()`` folds them into
the few float32 matrices one step needs (used by the numpy runtime and the ONNX export):

- feature scaling folded into layer 0: W (x - mean) / std = (W / std) x - (W / std) mean;
- [W_ih | W_hh | b_ih + b_hh] stacked so one matrix product per layer does everything
  (the input buffer carries a constant 1 column for the bias);
- gate rows reordered from PyTorch's (i, f, g, o) to (i, f, o, g): the three sigmoid
  gates are one contiguous block;
- ``out_scale`` folded into the head (into its correction rows b only, for a "gated"
  or "rate" output head, whose first K·M rows are the gain logits a: x̂' = g x_c + b with
  g = 1 + tanh a, or g = 1 - exp(-dt / tau), tau = RATE_TAU0 e^a).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from faceclean.channels import repeated
from faceclean.errors import FacecleanError
from faceclean.learned import formats
from faceclean.learned.formats import LSTM as FORMAT

OUTPUTS = ("additive", "gated", "rate")  # output heads (docs/ARCHITECTURE.md)
RATE_TAU0 = 0.002  # s, "rate" head: time constant tau = RATE_TAU0 e^a of a zero network
RATE_A_MAX = 15.0  # "rate" head: a is clamped to [-RATE_A_MAX, RATE_A_MAX]


@dataclass(frozen=True)
class Fused:
    """Step matrices, float32, for inputs laid out as rows.

    layers[0]: (F + H + 1, 4H) for [features | h_0 | 1];
    layers[l]: (2H + 1, 4H) for [input_l | h_l | 1], l >= 1;
    head:      (H + 1, K*M) for [top output | 1], or (H + 1, 2*K*M) = [a | out_scale b]
               for a gated or rate output head; gates in (i, f, o, g) order.
    ``half_sigmoid``: the (i, f, o) columns are pre-scaled by 1/2, so that one tanh over
    all 4H gates gives sigmoid(a) = (1 + tanh(a / 2)) / 2 for them (numpy's tanh is SIMD).
    """

    layers: tuple[np.ndarray, ...]
    head: np.ndarray
    half_sigmoid: bool = False


@dataclass(frozen=True)
class LSTMWeights:
    """A checkpoint's config and arrays (float32), validated."""

    config: dict[str, Any]
    feat_mean: np.ndarray  # (F,)
    feat_std: np.ndarray  # (F,)
    out_scale: np.ndarray  # (K*M,)
    w_ih: tuple[np.ndarray, ...]  # (4H, in_l) per layer
    w_hh: tuple[np.ndarray, ...]  # (4H, H)
    b_ih: tuple[np.ndarray, ...]  # (4H,)
    b_hh: tuple[np.ndarray, ...]  # (4H,)
    head_w: np.ndarray  # (K*M, H); gated: (2*K*M, H), gain logits a then corrections b
    head_b: np.ndarray  # (K*M,); gated: (2*K*M,)

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.config["channels"])

    @property
    def K(self) -> int:  # noqa: N802 (the paper's symbol)
        return int(self.config["K"])

    @property
    def hidden(self) -> int:
        return int(self.config["hidden"])

    @property
    def layers(self) -> int:
        return len(self.w_ih)

    @property
    def output(self) -> str:
        """The output head: "additive", "gated" or "rate" (module docstring)."""
        return str(self.config.get("output", "additive"))

    @property
    def gated(self) -> bool:
        """Whether the output head is "gated": x̂' = (1 + tanh a) x_c + out_scale b."""
        return self.output == "gated"

    @property
    def value_range(self) -> tuple[float, float]:
        lo, hi = self.config.get("value_range", (0.0, 1.0))
        return float(lo), float(hi)

    @classmethod
    def load(cls, path: str | os.PathLike) -> LSTMWeights:
        """Read and check a ``faceclean-lstm/1`` .npz; FacecleanError if it is not one."""
        return cls.from_arrays(formats.read_arrays(path), Path(path).name)

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], label: str = "model") -> LSTMWeights:
        """Build from the checkpoint's key -> array mapping (see docs/ARCHITECTURE.md)."""
        config = read_config(arrays, label, FORMAT, ("K", "hidden", "layers"))

        def get(key: str) -> np.ndarray:
            if key not in arrays:
                raise FacecleanError(f"{label}: missing array {key!r}")
            if arrays[key].dtype.kind not in "iuf":  # text, complex, bool: not weights
                raise FacecleanError(f"{label}: {key} holds {arrays[key].dtype} values")
            return np.asarray(arrays[key], dtype=np.float32)

        try:
            n_layers = int(config["layers"])
            M, K, H = len(config["channels"]), int(config["K"]), int(config["hidden"])
        except (KeyError, TypeError, ValueError) as e:
            raise FacecleanError(f"{label}: bad config ({e})") from None
        output = config.get("output", "additive")
        if output not in OUTPUTS:
            raise FacecleanError(f"{label}: unknown output head {output!r}")
        F = M * (1 + 2 * K)
        R = K * M * (1 if output == "additive" else 2)  # head rows
        w = cls(
            config=config,
            feat_mean=get("feat_mean"),
            feat_std=get("feat_std"),
            out_scale=get("out_scale"),
            w_ih=tuple(get(f"lstm.{i}.w_ih") for i in range(n_layers)),
            w_hh=tuple(get(f"lstm.{i}.w_hh") for i in range(n_layers)),
            b_ih=tuple(get(f"lstm.{i}.b_ih") for i in range(n_layers)),
            b_hh=tuple(get(f"lstm.{i}.b_hh") for i in range(n_layers)),
            head_w=get("head.w"),
            head_b=get("head.b"),
        )
        shapes = {
            "feat_mean": (w.feat_mean.shape, (F,)),
            "feat_std": (w.feat_std.shape, (F,)),
            "out_scale": (w.out_scale.shape, (K * M,)),
            "head.w": (w.head_w.shape, (R, H)),
            "head.b": (w.head_b.shape, (R,)),
        }
        for i in range(n_layers):
            shapes[f"lstm.{i}.w_ih"] = (w.w_ih[i].shape, (4 * H, F if i == 0 else H))
            shapes[f"lstm.{i}.w_hh"] = (w.w_hh[i].shape, (4 * H, H))
            shapes[f"lstm.{i}.b_ih"] = (w.b_ih[i].shape, (4 * H,))
            shapes[f"lstm.{i}.b_hh"] = (w.b_hh[i].shape, (4 * H,))
        for key, (got, want) in shapes.items():
            if got != want:
                raise FacecleanError(f"{label}: {key} has shape {got}, expected {want}")
        if n_layers < 1 or K < 1:
            raise FacecleanError(f"{label}: needs at least one layer and K >= 1")
        if not np.all(w.feat_std > 0):
            raise FacecleanError(f"{label}: feat_std must be positive")
        arrays_of = {"feat_mean": w.feat_mean, "out_scale": w.out_scale, "head.w": w.head_w}
        arrays_of |= {"head.b": w.head_b, **{f"lstm.{i}": w.w_ih[i] for i in range(n_layers)}}
        for key, a in arrays_of.items():
            if not np.isfinite(a).all():
                raise FacecleanError(f"{label}: {key} holds non-finite numbers")
        return w

    def fused(self, half_sigmoid: bool = False) -> Fused:
        """The folded step matrices (see the module docstring and ``Fused``)."""
        H = self.hidden
        gate_scale = np.ones((4 * H, 1))
        if half_sigmoid:
            gate_scale[: 3 * H] = 0.5  # rows (i, f, o) after reordering
        order = np.r_[0:H, H : 2 * H, 3 * H : 4 * H, 2 * H : 3 * H]  # (i,f,g,o) -> (i,f,o,g)
        layers = []
        for i in range(self.layers):
            w_ih, bias = self.w_ih[i].astype(np.float64), (self.b_ih[i] + self.b_hh[i])
            bias = bias.astype(np.float64)
            if i == 0:  # fold the feature scaling (float64, then rounded once)
                w_ih = w_ih / self.feat_std.astype(np.float64)
                bias = bias - w_ih @ self.feat_mean.astype(np.float64)
            stacked = np.concatenate([w_ih, self.w_hh[i], bias[:, None]], axis=1)  # (4H, in+H+1)
            stacked = stacked[order] * gate_scale
            layers.append(np.ascontiguousarray(stacked.T, dtype=np.float32))
        scale = self.out_scale.astype(np.float64)[:, None]
        if self.output != "additive":  # the gain logits a are not scaled
            scale = np.concatenate([np.ones_like(scale), scale])
        head = np.concatenate([self.head_w * scale, self.head_b[:, None] * scale], axis=1)
        head = np.ascontiguousarray(head.T, dtype=np.float32)
        return Fused(tuple(layers), head, half_sigmoid)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The checkpoint's key -> array mapping (inverse of ``from_arrays``)."""
        arrays = {
            "config": np.array(json.dumps(self.config)),
            "feat_mean": self.feat_mean,
            "feat_std": self.feat_std,
            "out_scale": self.out_scale,
            "head.w": self.head_w,
            "head.b": self.head_b,
        }
        for i in range(self.layers):
            arrays[f"lstm.{i}.w_ih"], arrays[f"lstm.{i}.w_hh"] = self.w_ih[i], self.w_hh[i]
            arrays[f"lstm.{i}.b_ih"], arrays[f"lstm.{i}.b_hh"] = self.b_ih[i], self.b_hh[i]
        return arrays

    def save(self, path: str | os.PathLike) -> None:
        """Write a ``faceclean-lstm/1`` .npz atomically."""
        from faceclean.io.atomic import atomic_open

        with atomic_open(path, "wb") as f:
            np.savez(f, **self.to_arrays())

    @classmethod
    def random(
        cls,
        channels: tuple[str, ...] | list[str],
        *,
        hidden: int = 128,
        layers: int = 2,
        seed: int = 0,
        gain: float = 1.0,
        output: str = "additive",
    ) -> LSTMWeights:
        """An untrained model with PyTorch's default init U(-1/sqrt(H), 1/sqrt(H)), seeded.

        For tests and benchmarks; ``gain`` scales the head (0 gives a model that follows
        its input exactly); ``output`` "gated" or "rate" gives a head of 2M rows.
        """
        rng = np.random.default_rng(seed)
        M, H = len(channels), hidden
        R = M if output == "additive" else 2 * M  # head rows
        F, bound = 3 * M, 1.0 / np.sqrt(H)

        def u(*shape: int) -> np.ndarray:
            return rng.uniform(-bound, bound, shape).astype(np.float32)

        config = {
            "format": FORMAT,
            "channels": list(channels),
            "K": 1,
            "hidden": H,
            "layers": layers,
            "value_range": [0.0, 1.0],
            "dropout": 0.3,
            "output": output,
            "note": f"random init, seed {seed}",
        }
        return cls(
            config=config,
            feat_mean=rng.uniform(0.0, 0.3, F).astype(np.float32),
            feat_std=rng.uniform(0.5, 2.0, F).astype(np.float32),
            out_scale=np.full(M, 0.5, np.float32),
            w_ih=tuple(u(4 * H, F if i == 0 else H) for i in range(layers)),
            w_hh=tuple(u(4 * H, H) for i in range(layers)),
            b_ih=tuple(u(4 * H) for i in range(layers)),
            b_hh=tuple(u(4 * H) for i in range(layers)),
            head_w=u(R, H) * np.float32(gain),
            head_b=u(R) * np.float32(gain),
        )


# Integer fields of a config and their ranges (a checkpoint is untrusted input).
_INTS = {"K": (1, 8), "hidden": (1, 4096), "layers": (1, 64)}


def read_config(
    arrays: dict[str, np.ndarray], label: str, fmt: str, ints: Sequence[str] = ("K",)
) -> dict[str, Any]:
    """The checkpoint's JSON ``config``, checked: strict JSON object of format ``fmt``;
    ``channels`` 1-4096 text names; the ``ints`` fields integers in range (``_INTS``);
    ``value_range`` two finite numbers lo < hi; ``alpha``, ``feat_clip`` finite numbers.
    One line (FacecleanError) for anything else, never an error later."""
    from faceclean import strict_json

    raw = arrays.get("config")
    if raw is None or raw.dtype.kind not in "US" or raw.size != 1:
        raise FacecleanError(f"{label}: no readable 'config' (a text array)")
    config = strict_json.loads(str(raw.reshape(())[()]), f"{label}: config")
    if not isinstance(config, dict) or config.get("format") != fmt:
        raise FacecleanError(f"{label}: not a {fmt} checkpoint")
    names = config.get("channels")
    if not isinstance(names, list) or not 1 <= len(names) <= 4096:
        raise FacecleanError(f"{label}: config 'channels' must list 1 to 4096 names")
    for n in names:
        if not isinstance(n, str) or not n.isprintable():
            raise FacecleanError(f"{label}: config channel {str(n)[:40]!r} is not a name")
    if (twice := repeated(names)) is not None:  # one name 52 times cleaned nothing, unsaid
        raise FacecleanError(f"{label}: config channel {twice[:40]!r} is listed twice")
    for key in ints:
        v, (lo, hi) = config.get(key), _INTS[key]
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise FacecleanError(f"{label}: config {key!r} must be an integer in [{lo}, {hi}]")
    vr = config.get("value_range", [0.0, 1.0])
    ok = isinstance(vr, list) and len(vr) == 2 and all(_number(v) for v in vr)
    if not ok or not vr[0] < vr[1]:
        raise FacecleanError(f"{label}: config 'value_range' must be [low, high], low < high")
    for key in ("alpha", "feat_clip"):
        if key in config and not _number(config[key]):
            raise FacecleanError(f"{label}: config {key!r} must be a finite number")
    if not isinstance(config.get("output", "additive"), str):
        raise FacecleanError(f"{label}: config 'output' must be a name")
    return config


def _number(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and abs(v) < 1e300
