"""Training of the paper's non-recurrent baselines (SPEC section 3): FC (torch) and GBT.

Both learn the truth's K = 4 backward time-derivatives at the newest frame from the
input's features ``[x, d^(1..K)[n+1], d^(1..K)[n]]`` (see faceclean.learned.derivative_net,
whose feature pass is reused here, so training and runtime see the same numbers).

Data: every training take is augmented (dataset.augment: gains, offsets, time-warp,
mirroring), its simulator parameters drawn from the "mixed" preset, and it is corrupted
three times, at the drawn rate f and resampled at 2f and f/2 (the paper's ×2 / ×½
augmentation; rates kept in 12-240 Hz). Frames whose derivatives reach back past a
(re)start are left out. 10 % "still face" samples are added (random pose, zero
derivatives in and out; see :func:`with_still_faces`).

Loss, L_der: Σ_k mean((x̂^(k) − x_gt^(k)) / σ_k)², each order scaled by its training std
σ_k (an unscaled 4th derivative is ~fps⁴ larger and would be all the loss sees).

- FC: one whole-face MLP, (1 + 2K)·M inputs (standardised, clipped to ±5) -> hidden
  layers (ReLU, dropout) -> K·M outputs; Adam, lr 1e-3, α_r = 0.9.
- GBT: scikit-learn HistGradientBoostingRegressor, one ensemble per order, shared by all
  channels: the samples are channels, with the 1 + 2K raw features plus the channel's
  group index (eyes, brows, jaw, mouth, cheeks_nose); depth <= 5, 30 trees for the first
  order (the one the blend feeds to the output), 10 for each higher one; exported as
  complete binary trees with raw-value thresholds; α_r = 0.97.
"""

from __future__ import annotations

import dataclasses
import io
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from faceclean import strict_json
from faceclean.channels import ARKIT52
from faceclean.datasets import dataset, simulate
from faceclean.errors import FacecleanError
from faceclean.io.atomic import atomic_write
from faceclean.learned import formats
from faceclean.learned.derivative_net import GROUP_NAMES, DerivativeFeatures, group_index

K = 4
ALPHA = {"fc": 0.9, "gbt": 0.97}
FACTORS = (1.0, 2.0, 0.5)  # rate multipliers of the ×2 / ×½ augmentation
FEAT_CLIP = 5.0  # FC: standardised features kept within ±5
STILL = 0.1  # share of "still face" samples added to the training frames


def training_data(
    takes: Sequence[dataset.Take],
    seed: int,
    repeats: int = 1,
    preset: str = "mixed",
    factors: Sequence[float] = FACTORS,
) -> tuple[np.ndarray, np.ndarray]:
    """(features (n, 52, 1 + 2K), targets (n, 52, K)) float32 from every take."""
    extract = DerivativeFeatures(K=K)
    feats, targets = [], []
    seeds = np.random.SeedSequence(seed).spawn(len(takes) * repeats)
    for i, child in enumerate(seeds):
        take = takes[i % len(takes)]
        rng = np.random.default_rng(child)
        clean = dataset.augment(take.animation, rng, dataset.DEFAULT_AUGMENTATION)
        params = simulate.sample_params(rng, preset)
        for f in factors:
            p = dataclasses.replace(params, fps=float(np.clip(params.fps * f, 12.0, 240.0)))
            noisy, truth = simulate.apply(clean, p, rng)
            noisy = noisy.with_values(noisy.arkit()[0])
            # The truth seen at the frames the tracker delivered: the same steps advance.
            truth = noisy.with_values(np.where(noisy.valid[:, None], truth.arkit()[0], np.nan))
            x, age = extract.features(noisy)
            y, _ = extract.features(truth)
            ok = (age[:, 0] >= K) & np.isfinite(y).all(axis=(1, 2))
            feats.append(x[ok].astype(np.float32))
            targets.append(y[ok][..., 1 : K + 1].astype(np.float32))
    if not feats:
        raise FacecleanError("no training frames")
    return np.concatenate(feats), np.concatenate(targets)


def with_still_faces(
    feats: np.ndarray, targets: np.ndarray, fraction: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Append ``fraction`` × n "still face" samples: random poses (each channel uniform in
    [0, 1]), zero input derivatives, zero target derivatives. A face held still stays
    still, whatever the pose (without them a whole-face net drifts on unusual poses)."""
    n = int(round(fraction * len(feats)))
    rng = np.random.default_rng([seed, 1])
    still = np.zeros((n, *feats.shape[1:]), feats.dtype)
    still[..., 0] = rng.uniform(0.0, 1.0, (n, feats.shape[1]))
    return np.concatenate([feats, still]), np.concatenate([targets, np.zeros_like(targets[:n])])


class FCNet(nn.Module):
    """The FC baseline: (n, M, 1 + 2K) features -> (n, M, K) derivatives, physical units."""

    def __init__(self, M: int = 52, hidden: Sequence[int] = (128, 128), dropout: float = 0.1):
        super().__init__()
        sizes = [M * (1 + 2 * K), *hidden, M * K]
        self.layers = nn.ModuleList(
            nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:], strict=True)
        )
        self.drop = nn.Dropout(dropout)
        self.M, self.hidden = M, list(hidden)
        for name, n in (("feat_mean", sizes[0]), ("out_mean", M * K)):
            self.register_buffer(name, torch.zeros(n))
        for name, n in (("feat_std", sizes[0]), ("out_std", M * K)):
            self.register_buffer(name, torch.ones(n))

    def scaled(self, feats: torch.Tensor) -> torch.Tensor:
        """Standardised outputs (n, K·M) order-major, the space the loss lives in."""
        n = feats.shape[0]
        h = (feats.transpose(1, 2).reshape(n, -1) - self.feat_mean) / self.feat_std
        h = h.clamp(-FEAT_CLIP, FEAT_CLIP)
        for i, layer in enumerate(self.layers):
            h = layer(h)
            if i < len(self.layers) - 1:
                h = self.drop(torch.relu(h))
        return h

    def forward(self, feats: torch.Tensor) -> torch.Tensor:
        out = self.scaled(feats) * self.out_std + self.out_mean
        return out.reshape(feats.shape[0], K, self.M).transpose(1, 2)


def _std(a: np.ndarray, axis) -> np.ndarray:
    s = a.std(axis=axis)
    return np.where(s > 1e-8, s, 1.0)


def _save(path: str | os.PathLike, config: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
    buf = io.BytesIO()
    np.savez_compressed(buf, config=np.array(strict_json.dumps(config)), **arrays)  # NaN: null
    atomic_write(path, buf.getvalue())


def save_fc(model: FCNet, path: str | os.PathLike, extra: dict[str, Any] | None = None) -> None:
    """Write an FC checkpoint (``faceclean-fc/1``) readable by learned.derivative_net."""
    config = {
        "format": formats.FC,
        "channels": list(ARKIT52[: model.M]),
        "K": K,
        "alpha": ALPHA["fc"],
        "value_range": [0.0, 1.0],
        "hidden": model.hidden,
        "feat_clip": FEAT_CLIP,
        **(extra or {}),
    }
    arrays = {
        k: getattr(model, k).detach().numpy().astype(np.float32)
        for k in ("feat_mean", "feat_std", "out_mean", "out_std")
    }
    for i, layer in enumerate(model.layers):
        arrays[f"fc.{i}.w"] = layer.weight.detach().numpy().astype(np.float32)
        arrays[f"fc.{i}.b"] = layer.bias.detach().numpy().astype(np.float32)
    _save(path, config, arrays)


def fit_fc(
    feats: np.ndarray,
    targets: np.ndarray,
    *,
    seed: int = 0,
    epochs: int = 8,
    hidden: Sequence[int] = (128, 128),
    batch: int = 512,
    progress: Callable[[str], None] | None = None,
) -> FCNet:
    """Train the FC net with Adam (lr 1e-3) on L_der over standardised orders."""
    torch.manual_seed(seed)
    n, m, _ = feats.shape
    model = FCNet(m, hidden)
    x = torch.from_numpy(feats)
    y = torch.from_numpy(targets.transpose(0, 2, 1).reshape(n, -1).copy())  # (n, K·M)
    flat = feats.transpose(0, 2, 1).reshape(n, -1)
    model.feat_mean.copy_(torch.from_numpy(flat.mean(0)))
    model.feat_std.copy_(torch.from_numpy(_std(flat, 0)))
    model.out_mean.copy_(y.mean(0))
    # σ per (order, channel); orders balanced: Σ_k mean over the order's channels.
    model.out_std.copy_(torch.from_numpy(_std(y.numpy(), 0)))
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(seed)
    model.train()
    for epoch in range(epochs):
        order, total = torch.randperm(n, generator=gen), 0.0
        for s in range(0, n, batch):
            idx = order[s : s + batch]
            err = (model.scaled(x[idx]) - (y[idx] - model.out_mean) / model.out_std) ** 2
            loss = err.reshape(len(idx), K, m).mean(dim=(0, 2)).sum()  # L_der
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
        if progress:
            progress(f"fc epoch {epoch + 1}/{epochs}: L_der {total / n:.4f}")
    return model.eval()


def _complete(nodes: np.ndarray, depth: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One sklearn tree as a complete binary tree of ``depth`` levels, in implicit layout
    (children of i: 2i+1, 2i+2): feature, threshold (2^D - 1,), leaf value (2^D,). A leaf
    above the last level becomes splits that always go left (threshold +inf) down to
    copies of itself."""
    n_in = 2**depth - 1
    feat, thr, val = np.zeros(n_in, np.int64), np.full(n_in, np.inf), np.zeros(2**depth)
    stack = [(0, 0, 0)]  # (sklearn node, position, level)
    while stack:
        node, pos, level = stack.pop()
        leaf = bool(nodes["is_leaf"][node])
        if level == depth:
            val[pos - n_in] = nodes["value"][node]
            continue
        if leaf:
            stack += [(node, 2 * pos + 1, level + 1), (node, 2 * pos + 2, level + 1)]
        else:
            feat[pos], thr[pos] = nodes["feature_idx"][node], nodes["num_threshold"][node]
            stack += [(int(nodes["left"][node]), 2 * pos + 1, level + 1)]
            stack += [(int(nodes["right"][node]), 2 * pos + 2, level + 1)]
    return feat, thr, val


def export_gbt(
    regressors: Sequence[Any],
    out_std: np.ndarray,
    path: str | os.PathLike,
    extra: dict[str, Any] | None = None,
) -> None:
    """Flatten fitted HistGradientBoostingRegressors (one per order) into a GBT checkpoint."""
    trees = [(k, p.nodes) for k, reg in enumerate(regressors) for (p,) in reg._predictors]
    if any(nodes["is_categorical"].any() for _, nodes in trees):
        raise FacecleanError("categorical splits are not supported")
    depth = max(int(nodes["depth"].max()) for _, nodes in trees)
    feat, thr, val = zip(*(_complete(nodes, depth) for _, nodes in trees), strict=True)
    config = {
        "format": formats.GBT,
        "channels": list(ARKIT52),
        "K": K,
        "alpha": ALPHA["gbt"],
        "value_range": [0.0, 1.0],
        "features": "x, d1..d4[n+1], d1..d4[n] (raw), channel group index",
        "groups": [*GROUP_NAMES, "other"],
        **(extra or {}),
    }
    arrays = {
        "tree.feature": np.stack(feat).astype(np.int8),
        "tree.threshold": np.stack(thr),
        "tree.value": np.stack(val),
        "tree.order": np.array([k for k, _ in trees], np.int8),
        "baseline": np.array([float(np.ravel(r._baseline_prediction)[0]) for r in regressors]),
        "out_std": np.asarray(out_std, np.float64),
    }
    _save(path, config, arrays)


def fit_gbt(
    feats: np.ndarray,
    targets: np.ndarray,
    *,
    seed: int = 0,
    iterations: Sequence[int] = (30, 10, 10, 10),
    depth: int = 5,
    learning_rate: float = 0.2,
    max_samples: int = 1_500_000,
    progress: Callable[[str], None] | None = None,
) -> tuple[list[Any], np.ndarray]:
    """(one fitted regressor per order, σ (K,)): L_der on per-channel samples."""
    from sklearn.ensemble import HistGradientBoostingRegressor

    n, m, f = feats.shape
    groups = np.broadcast_to(group_index(ARKIT52[:m])[None, :, None], (n, m, 1))
    x = np.concatenate([feats, groups.astype(np.float32)], axis=-1).reshape(n * m, f + 1)
    y = targets.reshape(n * m, K)
    rng = np.random.default_rng(seed)
    if len(x) > max_samples:
        keep = rng.choice(len(x), max_samples, replace=False)
        x, y = x[keep], y[keep]
    x = x.astype(np.float64)
    sigma = _std(y.astype(np.float64), 0)
    regs = []
    for k in range(K):
        reg = HistGradientBoostingRegressor(
            max_iter=iterations[k],
            max_depth=depth,
            learning_rate=learning_rate,
            early_stopping=False,
            random_state=seed,
        )
        regs.append(reg.fit(x, y[:, k] / sigma[k]))
        if progress:
            progress(f"gbt order {k + 1}/{K}: {iterations[k]} trees")
    return regs, sigma


def train(
    arch: str,
    out: str | os.PathLike,
    *,
    data: str | os.PathLike | None = None,
    val_sources: Sequence[str] = (),
    seed: int = 0,
    repeats: int = 1,
    epochs: int = 8,
    iterations: Sequence[int] = (30, 10, 10, 10),
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Train ``arch`` ("fc" or "gbt") on the takes of every source not in ``val_sources``
    and write its checkpoint to ``out``; returns the config facts it stored."""
    if arch not in ALPHA:
        raise FacecleanError(f"unknown baseline {arch!r} (known: fc, gbt)")
    takes = dataset.load_takes(data)
    train_takes, _ = dataset.split(takes, val_sources=val_sources)
    start = time.perf_counter()
    feats, targets = training_data(train_takes, seed, repeats)
    feats, targets = with_still_faces(feats, targets, STILL, seed)
    if progress:
        progress(f"{len(feats)} training frames from {len(train_takes)} takes")
    facts: dict[str, Any] = {
        "val_sources": sorted(val_sources),
        "train_sources": sorted({t.source for t in train_takes}),
        "train_takes": [f"{t.source}/{t.name}" for t in train_takes],
        "seed": seed,
        "repeats": repeats,
        "frames": int(len(feats)),
        "augmentation": "dataset.augment + simulator 'mixed' at f, 2f, f/2",
        "loss": "L_der, orders scaled by their training std",
        "still_fraction": STILL,
    }
    if arch == "fc":
        model = fit_fc(feats, targets, seed=seed, epochs=epochs, progress=progress)
        facts["epochs"] = epochs
        facts["seconds"] = round(time.perf_counter() - start, 1)
        save_fc(model, out, facts)
    else:
        regs, sigma = fit_gbt(feats, targets, seed=seed, iterations=iterations, progress=progress)
        facts.update(iterations=list(iterations), depth=5, learning_rate=0.2)
        facts["seconds"] = round(time.perf_counter() - start, 1)
        export_gbt(regs, sigma, out, facts)
    return facts
