"""Training of the recurrent cleaner: closed loop over 200-frame chunks, CPU or DDP.

    faceclean train --val-sources neurosync --epochs 40 --out model.npz
    torchrun --nproc_per_node 2 -m faceclean.neural.train --epochs 40 --out model.npz

Every epoch draws fresh augmented, corrupted chunks (faceclean.datasets.dataset); the
model unrolls closed loop over each chunk from x̂[0] = x[0] and gradients flow through
it all. Adam (lr 1e-3), gradient clipping, seeded. After every epoch the model runs over
whole validation takes (sources never trained on; evaluation/harness.py's streams); the
best by validation loss is written to ``out``, and ``out`` minus ``.npz`` plus
``.last.npz`` keeps the latest weights with the optimizer state for ``--resume``.
Training stops early after ``patience`` epochs without improvement. Under torchrun
(WORLD_SIZE > 1) it is data-parallel: DDP with gloo on CPU, NCCL with CUDA; rank 0
validates and writes.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from faceclean.channels import ARKIT52
from faceclean.datasets import dataset
from faceclean.evaluation import harness
from faceclean.face.vertex_pairs import load_face
from faceclean.neural import checkpoint, distributed
from faceclean.neural.data import EpochStream
from faceclean.neural.losses import Loss, Weights
from faceclean.neural.model import LSTMCleaner
from faceclean.neural.validate import evaluate

Report = Callable[[dict[str, Any]], None]


@dataclass
class Config:
    """Everything a run depends on (stored in the checkpoint as ``train``)."""

    out: str = "model.npz"
    data: str | None = None  # takes folder; default settings.takes_dir()
    val_sources: tuple[str, ...] = ()  # whole sources held out; empty: 20 % of takes
    synthetic_minutes: float = 0.0  # fresh synthetic-performer minutes per epoch
    epochs: int = 40
    batch: int = 32
    seed: int = 0
    K: int = 1
    hidden: int = 128
    layers: int = 2
    dropout: float = 0.3
    output: str = "additive"  # output head: the paper's "additive", "gated" or "rate"
    lr: float = 1e-3
    clip: float = 1.0  # gradient norm
    patience: int = 8  # epochs without validation improvement before stopping
    preset: str = "mixed"  # simulator preset of the training chunks
    strength: float = 1.0
    weights: Weights = field(default_factory=Weights)
    mesh: str | None = None  # face mesh (npz/GLB); default the ARKit reference mesh
    resume: str | None = None
    max_batches: int | None = None  # per epoch (tests, smoke runs)
    threads: int = 1  # torch CPU threads per process


def last_path(out: str | os.PathLike) -> Path:
    """The resumable checkpoint beside ``out``: ``model.npz`` -> ``model.last.npz``."""
    p = Path(out)
    return p.with_name(p.stem + ".last.npz")


def feature_stats(
    model: LSTMCleaner, noisy: np.ndarray, truth: np.ndarray, times: np.ndarray
) -> None:
    """Set feat_mean/feat_std/out_scale from training chunks (B, T, M) at (B, T) s.

    Before training the estimate is unknown; the truth stands in for it: x̂ ~ x_gt,
    x̂^(k) ~ x_gt^(k), x_c^(k) ~ (x_i^(k-1)[n+1] - x_gt^(k-1)[n]) / dt, and the
    correction the head must make ~ (x_gt^(k-1)[n+1] - x_i^(k-1)[n+1]) / dt.
    """
    M, K = model.M, model.K
    dt = np.diff(times, axis=1)[..., None]  # (B, T-1, 1) s
    g, x = truth.astype(np.float64), noisy.astype(np.float64)
    est, cor, fix = [g], [], []
    gk, xk = g, x
    for _ in range(K):
        n = gk.shape[1] - 1
        cor.append((xk[:, 1:] - gk[:, :-1]) / dt[:, :n])
        fix.append((gk[:, 1:] - xk[:, 1:]) / dt[:, :n])
        gk = (gk[:, 1:] - gk[:, :-1]) / dt[:, :n]
        xk = (xk[:, 1:] - xk[:, :-1]) / dt[:, :n]
        est.append(gk)
    groups = [est[0]] + est[1 : K + 1] + cor

    def stats(a: np.ndarray, floor: float) -> tuple[np.ndarray, np.ndarray]:
        a = a.reshape(-1, M)
        a = a[np.isfinite(a).all(1)]
        return a.mean(0), np.maximum(a.std(0), floor)

    mean, std = zip(*(stats(a, 1e-2 if i else 1e-3) for i, a in enumerate(groups)), strict=True)
    scale = [stats(a, 1e-2)[1] for a in fix]
    mean = np.concatenate(mean)
    mean[M:] = 0.0  # derivatives: centred at rest, as any face is on average
    with torch.no_grad():
        model.feat_mean.copy_(torch.tensor(mean, dtype=torch.float32))
        model.feat_std.copy_(torch.tensor(np.concatenate(std), dtype=torch.float32))
        model.out_scale.copy_(torch.tensor(np.concatenate(scale), dtype=torch.float32))


def _tensors(batch: dict[str, torch.Tensor]):
    """(noisy with NaN where the tracker lost the face, truth, times f32, valid)."""
    noisy = batch["noisy"].float().clone()
    noisy[~batch["observed"]] = float("nan")
    return noisy, batch["truth"].float(), batch["times"].float(), batch["valid"]


def train(cfg: Config, report: Report | None = None) -> dict[str, Any]:
    """Train; returns the best epoch's record. ``report`` receives progress events
    (dicts with ``event`` = "start", "batch", "epoch" or "stop"); only rank 0 reports."""
    report = report or (lambda _e: None)
    torch.set_num_threads(max(1, cfg.threads))
    rank, world, device = distributed.setup()
    try:
        return _train(cfg, report if rank == 0 else (lambda _e: None), rank, world, device)
    finally:
        distributed.teardown()


def _train(cfg: Config, report: Report, rank: int, world: int, device) -> dict[str, Any]:
    torch.manual_seed(cfg.seed)
    takes = dataset.load_takes(cfg.data)
    train_takes, val_takes = dataset.holdout(takes, cfg.val_sources, cfg.seed)
    face = load_face(cfg.mesh)
    loss_fn = Loss(ARKIT52, face, cfg.weights)
    stream = EpochStream(
        train_takes,
        cfg.seed,
        cfg.batch,
        rank=rank,
        world_size=world,
        synthetic_minutes=cfg.synthetic_minutes,
        preset=cfg.preset,
        strength=cfg.strength,
    )
    start_epoch, best, bad = 0, math.inf, 0
    if cfg.resume:
        model, saved, optim_arrays = checkpoint.load_training(cfg.resume)
        facts = saved.get("train_state", {})
        start_epoch, best, bad = (
            facts.get("epoch", -1) + 1,
            facts.get("best", math.inf),
            facts.get("bad", 0),
        )
    else:
        model = LSTMCleaner(ARKIT52, cfg.K, cfg.hidden, cfg.layers, cfg.dropout, output=cfg.output)
        first = dataset.epoch_chunks(
            train_takes, cfg.seed, 0, synthetic_minutes=cfg.synthetic_minutes, preset=cfg.preset
        )
        feature_stats(model, first.noisy, first.truth, first.times)
        optim_arrays = {}
    model.to(device)
    net = distributed.wrap(model, device)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    checkpoint.load_optimizer(model, opt, optim_arrays)
    val_streams = harness.streams(val_takes) if rank == 0 and val_takes else []
    start_model = None
    if cfg.resume and start_epoch == 0 and rank == 0 and val_streams:
        # Fine-tuning: the starting model is the bar; never write a model worse than it.
        val = evaluate(model, val_streams, loss_fn)
        best = float(np.mean([v["loss"] for v in val.values()]))
        start_model = cfg.resume
    facts = {
        "train": _jsonable(cfg),
        "train_sources": sorted({t.source for t in train_takes}),
        "val_sources": sorted({t.source for t in val_takes}),
        "val_takes": [f"{t.source}/{t.name}" for t in val_takes],
    }
    report({"event": "start", "epochs": cfg.epochs, "world": world, **facts})
    best_record: dict[str, Any] = {}
    for epoch in range(start_epoch, cfg.epochs):
        stream.set_epoch(epoch)
        model.train()
        t0, losses = time.perf_counter(), []
        batches = list(stream)[: cfg.max_batches]
        for i, batch in enumerate(batches):
            noisy, truth, times, valid = (a.to(device) for a in _tensors(batch))
            y, d, stepped = net(noisy, times, return_derivatives=True)
            loss, parts = loss_fn(y, d, stepped, noisy, truth, times, valid)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip)
            opt.step()
            losses.append(float(loss.detach()))
            report({"event": "batch", "epoch": epoch, "i": i, "n": len(batches), **parts,
                    "loss": losses[-1]})  # fmt: skip
        record: dict[str, Any] = {"epoch": epoch, "train_loss": float(np.mean(losses))}
        stop = improved = False
        if rank == 0:
            model.cpu()
            if val_streams:
                val = evaluate(model, val_streams, loss_fn)
                record["val"] = val
                score = float(np.mean([v["loss"] for v in val.values()]))
            else:
                score = record["train_loss"]
            record["score"], record["seconds"] = score, time.perf_counter() - t0
            improved = score < best
            best, bad = (score, 0) if improved else (best, bad + 1)
            stop = bad >= cfg.patience
            state = {"epoch": epoch, "best": best, "bad": bad}
            if improved:
                best_record = record
                checkpoint.save(model, cfg.out, extra={**facts, "best": record})
            checkpoint.save(model, last_path(cfg.out), {**facts, "train_state": state}, opt)
            model.to(device)
            report({"event": "epoch", "improved": improved, **record})
        if distributed.agree(stop, device):
            break
    if start_model is not None and not best_record:  # nothing beat it: out is the start
        from faceclean.io.atomic import atomic_write
        from faceclean.io.source import read_bytes

        if not Path(cfg.out).exists() or not Path(cfg.out).samefile(start_model):
            atomic_write(cfg.out, read_bytes(start_model, what="model file"))
        best_record = {"epoch": -1, "score": best, "start": True}
        report({"event": "stop", "best": best_record, "note": "no epoch beat the start"})
        return best_record
    report({"event": "stop", "best": best_record})
    return best_record


def _jsonable(cfg: Config) -> dict[str, Any]:
    d = dataclasses.asdict(cfg)
    d["val_sources"] = list(cfg.val_sources)
    return d


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m faceclean.neural.train`` (e.g. under torchrun): the train command."""
    from faceclean.cli import main as cli_main

    return cli_main(["train", *(argv if argv is not None else sys.argv[1:])])


if __name__ == "__main__":
    sys.exit(main())
