"""Validation of the recurrent cleaner on whole takes it never trained on.

Every take is corrupted by the simulator with a fixed seed under each condition, the
model runs closed loop over the whole stream (no chunking, as at run time), and the
SPEC section 5 measures compare it, and the raw input, with the truth.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import torch

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.evaluation import metrics, simulate
from faceclean.evaluation.dataset import Take
from faceclean.neural.losses import Loss
from faceclean.neural.model import LSTMCleaner

# condition -> (simulator preset, fps or None for the preset's own draw)
CONDITIONS: dict[str, tuple[str, float | None]] = {
    "iphone60": ("iphone", 60.0),
    "iphone30": ("iphone", 30.0),
    "iphone120": ("iphone", 120.0),
    "webcam": ("webcam", None),
}
QUICK = ("iphone60", "webcam")  # watched every epoch


def corrupted(
    takes: Sequence[Take], conditions: Sequence[str], seed: int = 7
) -> list[tuple[str, str, Animation, Animation]]:
    """(condition, take name, noisy, truth) for every take and condition, fixed seeds."""
    out = []
    for cond in conditions:
        preset, fps = CONDITIONS[cond]
        ci = list(CONDITIONS).index(cond)  # a condition's streams never depend on the others
        for ti, take in enumerate(takes):
            rng = np.random.default_rng([seed, ci, ti])
            params = simulate.sample_params(rng, preset)
            if fps is not None:
                params = dataclasses.replace(params, fps=fps)
            noisy, truth = simulate.apply(take.animation, params, rng)
            out.append((cond, f"{take.source}/{take.name}", noisy, truth))
    return out


@torch.no_grad()
def run(model: LSTMCleaner, noisy: Sequence[Animation]) -> list[np.ndarray]:
    """Model outputs (N_i, M) for each stream (batched, padded); missing frames NaN."""
    model.eval()
    arrays = [a.arkit(model.channels)[0] for a in noisy]
    T = max(len(a) for a in arrays)
    x = np.full((len(arrays), T, model.M), np.nan, np.float32)
    t = np.full((len(arrays), T), np.nan)
    for i, (a, anim) in enumerate(zip(arrays, noisy, strict=True)):
        x[i, : len(a)] = a
        t[i, : len(a)] = anim.times - anim.times[0]
    y = model(torch.from_numpy(x), torch.from_numpy(t).float()).numpy().astype(np.float64)
    out = []
    for i, a in enumerate(arrays):
        yi = y[i, : len(a)].copy()
        yi[np.isnan(a).all(1)] = np.nan
        out.append(yi)
    return out


def evaluate(
    model: LSTMCleaner,
    streams: Sequence[tuple[str, str, Animation, Animation]],
    loss: Loss | None = None,
    lag: bool = False,
) -> dict[str, dict[str, float]]:
    """Per condition: the model's and the raw input's measures, pooled over takes.

    Keys per condition: mse, raw_mse, mse_ratio, jitter_ratio, raw_jitter_ratio,
    blink_closure, raw_blink_closure, (lag_ms, raw_lag_ms), (loss).
    """
    outputs = run(model, [s[2] for s in streams])
    result: dict[str, dict[str, float]] = {}
    for cond in dict.fromkeys(s[0] for s in streams):
        rows = [i for i, s in enumerate(streams) if s[0] == cond]
        acc: dict[str, list[float]] = {}
        weights = []
        for i in rows:
            _, _, noisy, truth = streams[i]
            x, _ = noisy.arkit(ARKIT52)
            g, _ = truth.arkit(ARKIT52)
            y = _to_arkit(outputs[i], model.channels)
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
        if loss is not None:
            res["loss"] = _loss(model, loss, [streams[i] for i in rows])
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
def _loss(model: LSTMCleaner, loss: Loss, streams) -> float:
    """The training loss over whole streams (padded batch)."""
    xs = [s[2].arkit(model.channels)[0] for s in streams]
    gs = [s[3].arkit(model.channels)[0] for s in streams]
    T = max(len(a) for a in xs)
    x = np.full((len(xs), T, model.M), np.nan, np.float32)
    g = np.zeros((len(xs), T, model.M), np.float32)
    t = np.zeros((len(xs), T))
    valid = np.zeros((len(xs), T), bool)
    for i, (a, b, s) in enumerate(zip(xs, gs, streams, strict=True)):
        n = len(a)
        x[i, :n], g[i, :n] = a, np.nan_to_num(b)
        times = s[2].times - s[2].times[0]
        t[i, :n] = times
        t[i, n:] = times[-1] + np.arange(1, T - n + 1) / 60.0  # padding: invalid frames
        valid[i, :n] = ~np.isnan(a).all(1) & ~np.isnan(b).all(1)
    xt, tt = torch.from_numpy(x), torch.from_numpy(t).float()
    y, d, stepped = model(xt, tt, return_derivatives=True)
    total, _ = loss(y, d, stepped, xt, torch.from_numpy(g), tt, torch.from_numpy(valid))
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
