"""Self-describing, pickle-free checkpoints of :class:`LSTMCleaner` (docs/ARCHITECTURE.md).

An ``.npz`` with ``config`` (0-d unicode JSON), ``feat_mean``, ``feat_std``, ``out_scale``,
``lstm.{l}.w_ih|w_hh|b_ih|b_hh`` and ``head.w|b``, all float32 (``head`` holds 2·K·M
rows, gain logits then corrections, when ``config["output"]`` is "gated" or "rate").
Training checkpoints add the optimizer's state under ``optim.*`` keys (ignored by the
runtime).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from faceclean.errors import FacecleanError
from faceclean.learned import formats
from faceclean.learned.formats import LSTM as FORMAT
from faceclean.neural.model import LSTMCleaner

_LSTM = {"weight_ih": "w_ih", "weight_hh": "w_hh", "bias_ih": "b_ih", "bias_hh": "b_hh"}
_HEAD = {"weight": "w", "bias": "b"}


def arrays(model: LSTMCleaner) -> dict[str, np.ndarray]:
    """The model's tensors under checkpoint keys, float32 numpy."""
    out = {
        "feat_mean": model.feat_mean,
        "feat_std": model.feat_std,
        "out_scale": model.out_scale,
    }
    for i, cell in enumerate(model.lstm):
        for name, key in _LSTM.items():
            out[f"lstm.{i}.{key}"] = getattr(cell, name)
    for name, key in _HEAD.items():
        out[f"head.{key}"] = getattr(model.head, name)
    return {k: v.detach().cpu().numpy().astype(np.float32) for k, v in out.items()}


def save(
    model: LSTMCleaner,
    path: str | os.PathLike,
    extra: dict[str, Any] | None = None,
    optimizer: torch.optim.Optimizer | None = None,
) -> None:
    """Write ``model`` (and optionally its Adam state) atomically to ``path`` (.npz),
    once ``formats.write`` has checked it: every array finite, and the file as written
    loads in the numpy runtime (``LSTMWeights.from_arrays``); else one line, nothing
    written.

    ``extra``: JSON-serialisable training facts stored in the config (NaN: null).
    """
    from faceclean.learned.checkpoint import LSTMWeights

    config = {"format": FORMAT, **model.config(), **(extra or {})}
    data = arrays(model)
    if optimizer is not None:
        data.update(_optimizer_arrays(model, optimizer))
    label = Path(path).name
    formats.write(path, config, data, lambda a: LSTMWeights.from_arrays(a, label),
                  compressed=True)  # fmt: skip


def read(path: str | os.PathLike) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(config, arrays) of a checkpoint file; a foreign or malformed file is a FacecleanError."""
    p = Path(path)
    config, data = formats.read(p)  # the one model-file reader: bounded, never unpickles
    if config.get("format") != FORMAT:
        raise FacecleanError(f"{p.name}: not a {FORMAT} model")
    return config, data


def load(path: str | os.PathLike) -> LSTMCleaner:
    """Rebuild the model saved at ``path`` (eval mode, CPU, float32)."""
    model, _ = _load(path)
    return model


def load_training(
    path: str | os.PathLike,
) -> tuple[LSTMCleaner, dict[str, Any], dict[str, np.ndarray]]:
    """(model, config, optimizer arrays) of a training checkpoint, for ``--resume``."""
    model, (config, data) = _load(path)
    return model, config, {k: v for k, v in data.items() if k.startswith("optim.")}


def load_optimizer(
    model: LSTMCleaner, optimizer: torch.optim.Optimizer, arrays: dict[str, np.ndarray]
) -> None:
    """Restore Adam moments saved by :func:`save` into ``optimizer`` (built on ``model``)."""
    if not arrays:
        return
    state = optimizer.state_dict()
    names = [n for n, _ in model.named_parameters()]
    for i, name in enumerate(names):
        key = f"optim.{name}"
        if f"{key}.exp_avg" not in arrays:
            raise FacecleanError(f"optimizer state lacks {name}")
        state["state"][i] = {
            "step": torch.tensor(float(arrays[f"{key}.step"])),
            "exp_avg": torch.from_numpy(arrays[f"{key}.exp_avg"].copy()),
            "exp_avg_sq": torch.from_numpy(arrays[f"{key}.exp_avg_sq"].copy()),
        }
    optimizer.load_state_dict(state)


def _optimizer_arrays(model: LSTMCleaner, optimizer: torch.optim.Optimizer) -> dict:
    out = {}
    for name, p in model.named_parameters():
        st = optimizer.state.get(p)
        if not st:
            continue
        out[f"optim.{name}.step"] = np.array(float(st["step"]))
        out[f"optim.{name}.exp_avg"] = st["exp_avg"].detach().cpu().numpy()
        out[f"optim.{name}.exp_avg_sq"] = st["exp_avg_sq"].detach().cpu().numpy()
    return out


def _load(path: str | os.PathLike):
    config, data = read(path)
    name = Path(path).name
    try:
        model = LSTMCleaner(
            channels=[str(c) for c in config["channels"]],
            K=int(config["K"]),
            hidden=int(config["hidden"]),
            layers=int(config["layers"]),
            dropout=float(config.get("dropout", 0.3)),
            value_range=tuple(float(v) for v in config.get("value_range", (0.0, 1.0))),
            output=str(config.get("output", "additive")),
        )
    except (KeyError, TypeError, ValueError) as e:
        raise FacecleanError(f"{name}: bad model config ({e})") from None
    want = arrays(model)
    for key, ref in want.items():
        got = data.get(key)
        if got is None:
            raise FacecleanError(f"{name}: model lacks {key}")
        if got.shape != ref.shape:
            raise FacecleanError(f"{name}: {key} has shape {got.shape}, expected {ref.shape}")
        if not np.all(np.isfinite(got)):
            raise FacecleanError(f"{name}: {key} holds non-finite values")
    if np.any(data["feat_std"] <= 0):
        raise FacecleanError(f"{name}: feat_std must be positive")
    with torch.no_grad():
        model.feat_mean.copy_(torch.from_numpy(data["feat_mean"]))
        model.feat_std.copy_(torch.from_numpy(data["feat_std"]))
        model.out_scale.copy_(torch.from_numpy(data["out_scale"]))
        for i, cell in enumerate(model.lstm):
            for attr, key in _LSTM.items():
                getattr(cell, attr).copy_(torch.from_numpy(data[f"lstm.{i}.{key}"]))
        for attr, key in _HEAD.items():
            getattr(model.head, attr).copy_(torch.from_numpy(data[f"head.{key}"]))
    model.eval()
    return model, (config, data)
