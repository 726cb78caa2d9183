"""Training of the learned adaptive filter (faceclean.learned.adaptive), in torch.

    faceclean train --arch adaptive --val-sources sentien --out adaptive-sentien.npz

The torch model is the runtime's step, unrolled closed loop over 200-frame chunks
(B, T, M): the same features, the same GRU, the same One Euro stage, so that a checkpoint
runs identically in numpy (tests/learned/test_adaptive.py checks parity). Frames the tracker
lost (``observed`` False) hold the output and the state, as the runtime's time rules do.

Loss: mean squared error on the frames whose truth is known, plus ``w_acc`` times the
squared error of the second time-derivative (s⁴ · weight²/s⁴ units: jitter), both over
real, irregular times.

Every epoch draws fresh augmented chunks corrupted by faceclean.simulate's ``mixed``
preset (``wide`` on request; never the evaluation's second artefact model). After every
epoch the numpy runtime runs over whole validation takes (held-out sources, simulator,
fixed seeds: evaluation/harness.py's streams); the best epoch is written to ``out`` and
never one worse than the starting model when resuming (``--resume`` scores it first);
``out`` minus ``.npz`` plus ``.last.npz`` keeps the latest weights, Adam's moments and
the epoch for ``--resume`` of an interrupted run.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from faceclean import strict_json
from faceclean.channels import ARKIT52
from faceclean.datasets import dataset
from faceclean.evaluation import harness, metrics
from faceclean.filters import make
from faceclean.learned.adaptive import (
    A_MAX,
    A_MIN,
    DT_MIN,
    E0,
    F_MAX,
    F_SLOW,
    FORMAT,
    G_MAX,
    N_FEATURES,
    V0,
    Adaptive,
    AdaptiveWeights,
    group_matrix,
    mirror_index,
)

Report = Callable[[dict[str, Any]], None]


@dataclass
class AdaptiveConfig:
    """Everything an adaptive run depends on (stored in the checkpoint as ``train``)."""

    out: str = "adaptive.npz"
    data: str | None = None
    val_sources: tuple[str, ...] = ()  # whole sources held out; empty: 20 % of takes
    synthetic_minutes: float = 3.0  # fresh synthetic performers per epoch
    full_range: bool = False  # ... moving every channel through its range (performer)
    wide_augmentation: bool = False  # dataset.WIDE_AUGMENTATION of the real takes
    epochs: int = 8
    batch: int = 32
    seed: int = 0
    hidden: int = 32
    embed: int = 8
    lr: float = 1e-3
    clip: float = 1.0
    w_acc: float = 1e-7  # s⁴; weight of the second-derivative error
    patience: int = 3
    preset: str = "mixed"  # "wide" (+ full_range, wide_augmentation): see docs/MODEL.md
    strength: float = 1.0
    resume: str | None = None
    max_batches: int | None = None
    threads: int = 1


class AdaptiveNet(torch.nn.Module):
    """The step of faceclean.learned.adaptive in torch, unrolled over (B, T, M) chunks."""

    def __init__(self, channels: Sequence[str] = ARKIT52, hidden: int = 32, embed: int = 8):
        super().__init__()
        self.channels = tuple(channels)
        M = len(self.channels)
        self.M, self.H, self.E = M, hidden, embed
        oe = make("one-euro", names=self.channels)  # the tuned preset: the zero network
        mc, be, dc = (
            np.broadcast_to(getattr(oe, k), (M,)) for k in ("min_cutoff", "beta", "d_cutoff")
        )
        self.log_min_cutoff = torch.nn.Parameter(torch.tensor(np.log(mc), dtype=torch.float32))
        self.log_beta = torch.nn.Parameter(
            torch.tensor(np.log(np.maximum(be, 1e-6)), dtype=torch.float32)
        )
        self.register_buffer("d_cutoff", torch.tensor(dc.copy(), dtype=torch.float32))
        self.emb = torch.nn.Parameter(0.1 * torch.randn(M, embed))
        self.cell = torch.nn.GRUCell(N_FEATURES + embed, hidden)
        self.head = torch.nn.Linear(hidden, 2)
        self.boost = torch.nn.Parameter(torch.zeros(M))  # transient gain G_MAX tanh(boost)
        torch.nn.init.zeros_(self.head.weight)
        with torch.no_grad():
            self.head.bias.copy_(torch.tensor([0.0, -5.0]))  # fc = One Euro's, slope share ~0
        self.register_buffer("mirror", torch.tensor(mirror_index(self.channels)))
        self.register_buffer(
            "group", torch.tensor(group_matrix(self.channels), dtype=torch.float32)
        )

    def forward(self, x: Tensor, t: Tensor, observed: Tensor | None = None) -> Tensor:
        """x (B, T, M), t (B, T) s, observed (B, T) bool -> cleaned (B, T, M)."""
        B, T, M = x.shape
        mc, be = self.log_min_cutoff.exp(), self.log_beta.exp()
        y, edx, slow = x[:, 0], torch.zeros_like(x[:, 0]), x[:, 0]
        h = x.new_zeros(B * M, self.H)
        emb = self.emb.expand(B, M, -1)
        out = [y]
        for n in range(1, T):
            dt = (t[:, n] - t[:, n - 1]).clamp_min(DT_MIN)[:, None]  # (B, 1) s
            xn = x[:, n]
            e = xn - y
            edx_n = edx + alpha(self.d_cutoff, dt) * (e / dt - edx)
            en = e / E0
            f = torch.stack(
                [
                    en,
                    (edx_n / V0).clamp(-4.0, 4.0),
                    en.abs(),
                    en.abs() @ self.group.T,
                    en.abs().mean(1, keepdim=True).expand(-1, M),
                    en[:, self.mirror],
                    torch.log(60.0 * dt).expand(-1, M),
                ],
                -1,
            ).clamp(-F_MAX, F_MAX)
            f = torch.cat([f, emb], -1).reshape(B * M, -1)
            h_n = self.cell(f, h)
            o = self.head(h_n).reshape(B, M, 2)
            fc = (mc + be * edx_n.abs()) * torch.exp(o[..., 0].clamp(A_MIN, A_MAX))
            p = y + torch.sigmoid(o[..., 1]) * dt * edx_n
            y_n = p + alpha(fc, dt) * (xn - p)
            lo, hi = xn.clamp(max=0.0), xn.clamp(min=1.0)
            y_n = torch.minimum(torch.maximum(y_n, lo), hi)
            slow_n = slow + alpha(torch.tensor(F_SLOW), dt) * (y_n - slow)
            shown = y_n + G_MAX * torch.tanh(self.boost) * (y_n - slow_n)
            shown = torch.minimum(torch.maximum(shown, lo), hi)
            if observed is not None:  # a lost frame holds output and state
                keep = ~observed[:, n, None]
                y_n = torch.where(keep, y, y_n)
                edx_n = torch.where(keep, edx, edx_n)
                slow_n = torch.where(keep, slow, slow_n)
                h_n = torch.where(keep.repeat_interleave(M, 0), h, h_n)
                shown = torch.where(keep, out[-1], shown)
            y, edx, h, slow = y_n, edx_n, h_n, slow_n
            out.append(shown)
        return torch.stack(out, 1)

    def weights(self, extra: dict[str, Any] | None = None) -> AdaptiveWeights:
        """The runtime's checkpoint of this model."""
        a = {
            "emb": self.emb, "gru.w_ih": self.cell.weight_ih, "gru.w_hh": self.cell.weight_hh,
            "gru.b_ih": self.cell.bias_ih, "gru.b_hh": self.cell.bias_hh,
            "head.w": self.head.weight, "head.b": self.head.bias,
            "min_cutoff": self.log_min_cutoff.exp(), "beta": self.log_beta.exp(),
            "d_cutoff": self.d_cutoff, "boost": self.boost,
        }  # fmt: skip
        arrays = {k: v.detach().cpu().double().numpy().copy() for k, v in a.items()}
        config = {
            "format": FORMAT, "channels": list(self.channels), "hidden": self.H,
            "embed": self.E, **(extra or {}),
        }  # fmt: skip
        return AdaptiveWeights.from_arrays(config, arrays)

    @classmethod
    def from_weights(cls, w: AdaptiveWeights) -> AdaptiveNet:
        net = cls(w.channels, w.hidden, int(w.config["embed"]))
        a = {k: torch.tensor(v, dtype=torch.float32) for k, v in w.arrays.items()}
        with torch.no_grad():
            net.emb.copy_(a["emb"])
            net.cell.weight_ih.copy_(a["gru.w_ih"])
            net.cell.weight_hh.copy_(a["gru.w_hh"])
            net.cell.bias_ih.copy_(a["gru.b_ih"])
            net.cell.bias_hh.copy_(a["gru.b_hh"])
            net.head.weight.copy_(a["head.w"])
            net.head.bias.copy_(a["head.b"])
            net.log_min_cutoff.copy_(a["min_cutoff"].log())
            net.log_beta.copy_(a["beta"].log())
            net.d_cutoff.copy_(a["d_cutoff"])
            net.boost.copy_(a["boost"])
        return net


def alpha(cutoff: Tensor, dt: Tensor) -> Tensor:
    """The One Euro smoothing factor for ``cutoff`` Hz over ``dt`` s: 1 / (1 + tau / dt),
    tau = 1 / (2 pi cutoff) (the differentiable twin of the runtime's)."""
    return 1.0 / (1.0 + 1.0 / (2.0 * math.pi * cutoff * dt))


def loss(y: Tensor, truth: Tensor, t: Tensor, valid: Tensor, w_acc: float) -> Tensor:
    """MSE over valid frames + w_acc · MSE of the second derivative (real times)."""
    m = valid[..., None].float()
    mse = (((y - truth) ** 2) * m).sum() / (m.sum() * y.shape[-1]).clamp_min(1)
    if w_acc <= 0:
        return mse
    h = (t[:, 1:] - t[:, :-1]).clamp_min(1e-4)[..., None]  # (B, T-1, 1) s

    def second(v: Tensor) -> Tensor:
        s = (v[:, 1:] - v[:, :-1]) / h
        return 2.0 * (s[:, 1:] - s[:, :-1]) / (h[:, 1:] + h[:, :-1])

    m3 = (valid[:, 2:] & valid[:, 1:-1] & valid[:, :-2])[..., None].float()
    acc = (((second(y) - second(truth)) ** 2) * m3).sum() / (m3.sum() * y.shape[-1]).clamp_min(1)
    return mse + w_acc * acc


def score(w: AdaptiveWeights, streams: Sequence[harness.Stream]) -> float:
    """Validation score: MSE of the numpy runtime over whole streams, relative to the raw
    input's, averaged over conditions (lower is better; 1 = no better than raw)."""
    by_cond: dict[str, list[float]] = {}
    cleaner = Adaptive(weights=w)
    for cond, _name, noisy, truth in streams:
        x, _ = noisy.arkit()
        g, _ = truth.arkit()
        y = cleaner.clean(noisy.__class__.from_arkit(noisy.times, x)).values
        by_cond.setdefault(cond, []).append(metrics.mse(y, g) / max(metrics.mse(x, g), 1e-12))
    return float(np.mean([np.mean(v) for v in by_cond.values()]))


def train(cfg: AdaptiveConfig, report: Report | None = None) -> dict[str, Any]:
    """Train; returns the best record. ``report`` gets "start", "epoch" and "stop" events."""
    report = report or (lambda _e: None)
    torch.set_num_threads(max(1, cfg.threads))
    torch.manual_seed(cfg.seed)
    takes = dataset.load_takes(cfg.data)
    train_takes, val_takes = dataset.holdout(takes, cfg.val_sources, cfg.seed)
    val_streams = harness.streams(val_takes)
    facts = {
        "train": {**dataclasses.asdict(cfg), "val_sources": list(cfg.val_sources)},
        "train_sources": sorted({t.source for t in train_takes}),
        "val_sources": sorted({t.source for t in val_takes}),
        "val_takes": [f"{t.source}/{t.name}" for t in val_takes],
    }
    last = Path(cfg.out).with_name(Path(cfg.out).stem + ".last.npz")
    start_epoch, bad = 0, 0
    opt_state: dict[str, np.ndarray] = {}
    if cfg.resume:
        w0 = AdaptiveWeights.load(cfg.resume)
        net = AdaptiveNet.from_weights(w0)
        state = w0.config.get("train_state")
        if state:  # an interrupted run: continue where it stopped
            start_epoch, bad = state["epoch"] + 1, state["bad"]
            opt_state = _optimizer_arrays(cfg.resume)
        best = score(net.weights(), val_streams)  # the starting model is the bar
    else:
        net = AdaptiveNet(ARKIT52, cfg.hidden, cfg.embed)
        # The bar is the zero network, the tuned One Euro: never save an epoch worse.
        best = score(net.weights(), val_streams)
        w0 = net.weights()
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    _load_optimizer(opt, net, opt_state)
    report({"event": "start", "start_score": best, **facts})
    record: dict[str, Any] = {"epoch": start_epoch - 1, "score": best, "start": True}
    for epoch in range(start_epoch, cfg.epochs):
        t0 = time.perf_counter()
        chunks = dataset.epoch_chunks(
            train_takes, cfg.seed, epoch, synthetic_minutes=cfg.synthetic_minutes,
            full_range=cfg.full_range, preset=cfg.preset, strength=cfg.strength,
            augmentation=dataset.WIDE_AUGMENTATION if cfg.wide_augmentation else
            dataset.DEFAULT_AUGMENTATION,
        )  # fmt: skip
        rng = np.random.default_rng([cfg.seed, epoch])
        losses = []
        net.train()
        for i, b in enumerate(dataset.batches(chunks, cfg.batch, rng)):
            if cfg.max_batches is not None and i >= cfg.max_batches:
                break
            x, g = torch.from_numpy(b.noisy), torch.from_numpy(b.truth)
            t = torch.from_numpy(b.times.astype(np.float32))
            obs, valid = torch.from_numpy(b.observed), torch.from_numpy(b.valid)
            value = loss(net(x, t, obs), g, t, valid, cfg.w_acc)
            opt.zero_grad(set_to_none=True)
            value.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.clip)
            opt.step()
            losses.append(float(value.detach()))
        s = score(net.weights(), val_streams)
        improved = s < best
        best, bad = (s, 0) if improved else (best, bad + 1)
        rec = {"epoch": epoch, "train_loss": float(np.mean(losses)), "score": s,
               "seconds": time.perf_counter() - t0}  # fmt: skip
        if improved:
            record = rec
            net.weights({**facts, "best": rec}).save(cfg.out)
        state = {"epoch": epoch, "best": best, "bad": bad}
        _save_last(net.weights({**facts, "train_state": state}), opt, net, last)
        report({"event": "epoch", "improved": improved, **rec})
        if bad >= cfg.patience:
            break
    if record.get("start"):  # nothing beat it: the output is the start
        AdaptiveWeights.from_arrays({**w0.config, **facts, "best": record}, w0.arrays).save(cfg.out)
        report({"event": "stop", "best": record, "note": "no epoch beat the starting model"})
    else:
        report({"event": "stop", "best": record})
    return record


def _save_last(w: AdaptiveWeights, opt: torch.optim.Adam, net: AdaptiveNet, path: Path) -> None:
    """The resumable checkpoint: weights plus Adam's moments as optim.<i>.<key> arrays."""
    from faceclean.io.atomic import atomic_open

    arrays = {k: v.astype(np.float32) for k, v in w.arrays.items()}
    for i, p in enumerate(net.parameters()):
        st = opt.state.get(p, {})
        for key in ("exp_avg", "exp_avg_sq"):
            if key in st:
                arrays[f"optim.{i}.{key}"] = st[key].detach().numpy().copy()
        if "step" in st:
            arrays[f"optim.{i}.step"] = np.array(float(st["step"]))
    with atomic_open(path, "wb") as f:
        np.savez(f, config=np.array(strict_json.dumps(w.config)), **arrays)  # NaN: null


def _optimizer_arrays(path: str) -> dict[str, np.ndarray]:
    from faceclean.io.npz_safe import load_arrays

    return {k: v for k, v in load_arrays(path).items() if k.startswith("optim.")}


def _load_optimizer(opt: torch.optim.Adam, net: AdaptiveNet, arrays: dict[str, np.ndarray]) -> None:
    for i, p in enumerate(net.parameters()):
        if f"optim.{i}.exp_avg" in arrays:
            opt.state[p] = {
                "step": torch.tensor(float(arrays[f"optim.{i}.step"])),
                "exp_avg": torch.tensor(arrays[f"optim.{i}.exp_avg"]),
                "exp_avg_sq": torch.tensor(arrays[f"optim.{i}.exp_avg_sq"]),
            }
