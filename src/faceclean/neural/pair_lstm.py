"""The paper's LSTM trained on real (tracked, truth) pairs: its baseline on tracker data.

Pairs become chunks of 200 frames with an overlap of 150 (SPEC section 2), the tracked
channels mapped onto ARKit-52 (a channel the tracker lacks, tongueOut for MediaPipe, is 0
in and out, so it costs nothing), lost frames held from the last delivered one and left
out of the loss. Then the usual closed-loop training (neural/train.py's model and loss):
Adam, clipped gradients, best epoch by the validation pairs' loss, stopped after
``patience`` epochs without a better one. Every epoch also writes ``OUT.last.npz`` (the
weights, Adam's moments and where the run stands), so a long run killed at any point
continues from its last finished epoch with ``resume=True``: the batches of epoch e are
drawn from ``seed, e`` alone, so the epochs after a resume see what they would have.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from faceclean.channels import ARKIT52
from faceclean.datasets.dataset import Chunks, batches, concat
from faceclean.datasets.paired import Pair, performances
from faceclean.face.vertex_pairs import load_face
from faceclean.neural import checkpoint
from faceclean.neural.losses import Loss, Weights
from faceclean.neural.model import LSTMCleaner
from faceclean.neural.train import feature_stats, last_path

T, STRIDE = 200, 50  # frames per chunk; 200 - 150 overlap
Report = Callable[[dict[str, Any]], None]


def chunks(pairs: Sequence[Pair], stride: int = STRIDE) -> Chunks:
    """Every pair cut into (B, T, 52) chunks ``stride`` frames apart (the last one padded,
    padding not valid)."""
    parts = []
    for p in pairs:
        x, _ = p.tracked.arkit(ARKIT52)
        y, _ = p.truth.arkit(ARKIT52)
        t = p.tracked.times - p.tracked.times[0]
        observed = ~np.isnan(x).all(axis=1)
        x = _held(x, observed)
        truth_ok = ~np.isnan(y).any(axis=1)
        y = np.nan_to_num(y)
        for s in range(0, max(len(t) - T, 0) + 1, stride):
            n = min(T, len(t) - s)
            sl = slice(s, s + n)
            pad = T - n
            tt = t[sl] - t[s]
            if pad:
                step = np.median(np.diff(tt)) if n > 1 else 1 / 30
                tt = np.concatenate([tt, tt[-1] + step * np.arange(1, pad + 1)])
            parts.append(
                Chunks(
                    noisy=_pad(x[sl], pad)[None].astype(np.float32),
                    truth=_pad(y[sl], pad)[None].astype(np.float32),
                    times=tt[None],
                    valid=np.concatenate([observed[sl] & truth_ok[sl], np.zeros(pad, bool)])[None],
                    observed=np.concatenate([observed[sl], np.zeros(pad, bool)])[None],
                )
            )
    return concat(parts)


def _held(x: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Lost frames hold the last delivered one (0 before the first); NaN cells are 0."""
    out = np.nan_to_num(x)
    idx = np.maximum.accumulate(np.where(observed, np.arange(len(x)), -1))
    out = np.where((idx >= 0)[:, None], out[np.maximum(idx, 0)], 0.0)
    out[:, ARKIT52.index("tongueOut")] = 0.0
    return out


def _pad(a: np.ndarray, pad: int) -> np.ndarray:
    return np.concatenate([a, np.repeat(a[-1:], pad, axis=0)]) if pad else a


def train_lstm(
    train: Sequence[Pair],
    val: Sequence[Pair],
    out: str | Path,
    epochs: int = 8,
    hidden: int = 128,
    layers: int = 2,
    batch: int = 32,
    seed: int = 0,
    threads: int = 1,
    report: Report | None = None,
    stride: int = STRIDE,
    patience: int | None = None,
    lr: float = 1e-3,
    resume: bool = False,
) -> dict[str, Any]:
    """Train the paper's LSTM on pairs; the best epoch by validation loss goes to ``out``.
    ``stride``: frames between chunk starts (T: no overlap, a quarter of the work).
    ``patience``: stop after that many epochs without a better validation loss (None: run
    every epoch). ``resume``: continue ``OUT.last.npz`` where it exists (else start)."""
    report = report or (lambda _e: None)
    torch.set_num_threads(max(1, threads))
    torch.manual_seed(seed)
    tr = chunks(train, stride)
    tr.truth[..., ARKIT52.index("tongueOut")] = 0.0
    va = chunks(performances(val), T) if performances(val) else tr  # not on clips
    va.truth[..., ARKIT52.index("tongueOut")] = 0.0
    last = last_path(out)
    start, best, bad, record, optim_arrays = 0, math.inf, 0, {}, {}
    if resume and last.exists():
        model, saved, optim_arrays = checkpoint.load_training(last)
        state = saved.get("train_state", {})
        start, bad, record = state["epoch"] + 1, state["bad"], state["record"]
        best = record.get("val_mse", math.inf)
        report({"event": "resume", "epoch": start, "best": record})
    else:
        model = LSTMCleaner(ARKIT52, 1, hidden, layers, 0.3)
        feature_stats(model, tr.noisy, tr.truth, tr.times)
    loss_fn = Loss(ARKIT52, load_face(None), Weights())
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    checkpoint.load_optimizer(model, opt, optim_arrays)
    for epoch in range(start, epochs):
        if patience is not None and bad >= patience:
            break
        model.train()
        rng = np.random.default_rng([seed, epoch])
        losses = []
        for b in batches(tr, batch, rng):
            noisy, truth, times, valid = _tensors(b)
            y, d, stepped = model(noisy, times, return_derivatives=True)
            loss, _ = loss_fn(y, d, stepped, noisy, truth, times, valid)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
            losses.append(float(loss.detach()))
        model.eval()
        with torch.no_grad():
            noisy, truth, times, valid = _tensors(va)
            y = model(noisy, times)
            err = ((y - truth) ** 2)[valid]
            val_mse = float(err.mean())
        e = {"event": "epoch", "epoch": epoch, "train_loss": float(np.mean(losses)),
             "val_mse": val_mse}  # fmt: skip
        report(e)
        if val_mse < best:
            best, record, bad = val_mse, e, 0
            checkpoint.save(model, out, extra={"best": e, "trained_on": "pairs"})
        else:
            bad += 1
        state = {"epoch": epoch, "bad": bad, "record": record}
        checkpoint.save(model, last, extra={"train_state": state, "trained_on": "pairs"},
                        optimizer=opt)  # fmt: skip
    return record


def _tensors(c: Chunks):
    noisy = torch.from_numpy(np.ascontiguousarray(c.noisy)).float().clone()
    noisy[~torch.from_numpy(c.observed)] = float("nan")
    return (
        noisy,
        torch.from_numpy(np.ascontiguousarray(c.truth)).float(),
        torch.from_numpy(np.ascontiguousarray(c.times)).float(),
        torch.from_numpy(c.valid),
    )
