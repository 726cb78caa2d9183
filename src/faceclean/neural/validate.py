"""Validation of the recurrent cleaner on whole takes it never trained on.

The streams are the evaluation harness's (evaluation/harness.py ``streams``: the RESULTS
conditions and seeding), the model runs closed loop over the whole stream (no chunking,
as at run time), and the SPEC section 5 measures compare it, and the raw input, with the
truth.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.evaluation import metrics
from faceclean.evaluation.harness import Stream, pad, unpad
from faceclean.neural.losses import Loss
from faceclean.neural.model import LSTMCleaner


@torch.no_grad()
def run(model: LSTMCleaner, noisy: Sequence[Animation]) -> list[np.ndarray]:
    """Model outputs (N_i, M) for each stream (batched, padded); missing frames NaN."""
    model.eval()
    arrays = [a.arkit(model.channels)[0] for a in noisy]
    t, x = pad([a.times - a.times[0] for a in noisy], arrays)  # (B, T) s from 0, (B, T, M)
    y = model(torch.from_numpy(x.astype(np.float32)), torch.from_numpy(t).float())
    return unpad(y.numpy().astype(np.float64), arrays)


def evaluate(
    model: LSTMCleaner,
    streams: Sequence[Stream],
    loss: Loss | None = None,
    lag: bool = False,
) -> dict[str, dict[str, float]]:
    """Per condition: the model's and the raw input's measures, pooled over takes.

    Keys per condition: mse, raw_mse, mse_ratio, jitter_ratio, raw_jitter_ratio,
    blink_closure, raw_blink_closure, (lag_ms, raw_lag_ms), (loss).
    """
    outputs = run(model, [s[2] for s in streams])
    result = measure(outputs, streams, model.channels, lag)
    if loss is not None:
        for cond in result:
            rows = [s for s in streams if s[0] == cond]
            result[cond]["loss"] = _loss(model, loss, rows)
    return result


def measure(
    outputs: Sequence[np.ndarray],
    streams: Sequence[Stream],
    channels: Sequence[str],
    lag: bool = False,
) -> dict[str, dict[str, float]]:
    """:func:`evaluate`'s measures for any cleaner's outputs (N_i, M) on ``streams``, the
    columns named by ``channels`` (no loss: that is the torch model's)."""
    result: dict[str, dict[str, float]] = {}
    for cond in dict.fromkeys(s[0] for s in streams):
        rows = [i for i, s in enumerate(streams) if s[0] == cond]
        acc: dict[str, list[float]] = {}
        weights = []
        for i in rows:
            _, _, noisy, truth = streams[i]
            x, _ = noisy.arkit(ARKIT52)
            g, _ = truth.arkit(ARKIT52)
            y = _to_arkit(outputs[i], channels)
            missing = np.isnan(x).all(1)
            g = np.where(missing[:, None], np.nan, g)
            t = truth.times
            m = {
                "mse": metrics.mse(y, g),
                "raw_mse": metrics.mse(x, g),
                "jitter_ratio": metrics.jitter_ratio(t, y, g),
                "raw_jitter_ratio": metrics.jitter_ratio(t, x, g),
                "blink_closure": metrics.blink_closure(t, y, g, ARKIT52),
                "raw_blink_closure": metrics.blink_closure(t, x, g, ARKIT52),
            }
            if lag:
                m["lag_ms"] = metrics.lag_ms(t, y, g)
                m["raw_lag_ms"] = metrics.lag_ms(t, x, g)
            for k, v in m.items():
                acc.setdefault(k, []).append(v)
            weights.append(float((~missing).sum()))
        w = np.asarray(weights)
        res = {k: _wmean(v, w) for k, v in acc.items()}
        res["mse_ratio"] = res["mse"] / res["raw_mse"]
        result[cond] = res
    return result


def _to_arkit(y: np.ndarray, channels: Sequence[str]) -> np.ndarray:
    if tuple(channels) == ARKIT52:
        return y
    return Animation(np.arange(len(y), dtype=float), y, channels).arkit(ARKIT52)[0]


def _wmean(values: list[float], w: np.ndarray) -> float:
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    return float(np.sum(v[ok] * w[ok]) / np.sum(w[ok])) if ok.any() else float("nan")


@torch.no_grad()
def _loss(model: LSTMCleaner, loss: Loss, streams: Sequence[Stream]) -> float:
    """The training loss over whole streams (padded batch)."""
    times = [s.noisy.times - s.noisy.times[0] for s in streams]
    t, x = pad(times, [s.noisy.arkit(model.channels)[0] for s in streams])  # (B, T, M)
    _, g = pad(times, [s.truth.arkit(model.channels)[0] for s in streams])
    valid = ~np.isnan(x).all(-1) & ~np.isnan(g).all(-1)  # (B, T); padding: invalid
    for i, ti in enumerate(times):
        t[i, len(ti) :] = ti[-1] + np.arange(1, t.shape[1] - len(ti) + 1) / 60.0  # padding
    xt, tt = torch.from_numpy(x.astype(np.float32)), torch.from_numpy(t).float()
    gt = torch.from_numpy(np.nan_to_num(g).astype(np.float32))
    y, d, stepped = model(xt, tt, return_derivatives=True)
    total, _ = loss(y, d, stepped, xt, gt, tt, torch.from_numpy(valid))
    return float(total)


def table(results: dict[str, dict[str, float]]) -> str:
    """A markdown table of :func:`evaluate` results (with ``lag=True``): raw vs model."""
    lines = [
        "| condition | MSE raw | MSE model | ratio | jitter raw | jitter model "
        "| lag raw ms | lag model ms | blink raw | blink model |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for cond, r in results.items():
        lines.append(
            f"| {cond} | {r['raw_mse']:.5f} | {r['mse']:.5f} | {r['mse_ratio']:.2f} "
            f"| {r['raw_jitter_ratio']:.2f} | {r['jitter_ratio']:.2f} "
            f"| {r.get('raw_lag_ms', float('nan')):.1f} | {r.get('lag_ms', float('nan')):.1f} "
            f"| {r['raw_blink_closure']:.2f} | {r['blink_closure']:.2f} |"
        )
    return "\n".join(lines)
