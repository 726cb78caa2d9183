"""Fitting a tracker map (learned/tracker_map.py) on (tracked, truth) pairs.

The map is memoryless given its causal features (the pre-filtered input u and the resting
level r), and those do not depend on the map's weights: they are computed once per pair
by the numpy runtime itself (so training sees exactly what the cleaner computes), and the
map is fitted frame by frame. Ridge first (closed form: the linear part ``A u + c`` and
the baseline), then the hidden layer on the residual with Adam, early-stopped on
validation pairs (performances no training pair comes from). The pre-filter is chosen
from a few One Euro settings by the validation score of the whole map.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch

from faceclean.channels import ARKIT52
from faceclean.evaluation.paired import Pair
from faceclean.filters.one_euro import OneEuro
from faceclean.learned.formats import TRACKER_MAP
from faceclean.learned.tracker_map import MapWeights

# (min_cutoff Hz, beta, d_cutoff Hz) pre-filter candidates: none, light, medium, strong
PREFILTERS = ((3.0, 1.0, 1.0), (1.5, 0.5, 1.0), (0.8, 0.3, 1.0))
Report = Callable[[dict[str, Any]], None]


def channels(pairs: Sequence[Pair]) -> tuple[str, ...]:
    """The tracker's channels that are ARKit channels, in canonical order (inputs = outputs)."""
    have = set()
    for p in pairs:
        _, present = p.tracked.arkit(ARKIT52)
        have |= {n for n, ok in zip(ARKIT52, present, strict=True) if ok}
    return tuple(n for n in ARKIT52 if n in have)


def blank(names: Sequence[str], hidden: int, pre: tuple[float, float, float], rest: bool,
          prefilter: bool = True) -> MapWeights:  # fmt: skip
    """An identity map (y = u) of the right shapes: the start of every fit."""
    k, h = len(names), hidden
    arrays = {
        "min_cutoff": np.full(k, pre[0]),
        "beta": np.full(k, pre[1]),
        "d_cutoff": np.full(k, pre[2]),
        "mu": np.zeros(2 * k),
        "sd": np.ones(2 * k),
        "w1": np.zeros((h, 2 * k)),
        "b1": np.zeros(h),
        "w2": np.zeros((k, h)),
        "b2": np.zeros(k),
        "a": np.eye(k),
        "c": np.zeros(k),
    }
    config = {"format": TRACKER_MAP, "inputs": list(names), "outputs": list(names),
              "hidden": h, "rest": rest, "prefilter": prefilter}  # fmt: skip
    return MapWeights(config, arrays)


def features(w: MapWeights, pairs: Sequence[Pair]) -> tuple[np.ndarray, ...]:
    """(u, r, y) stacked over every valid frame of ``pairs``: (F, K) each, truth y (F, K).

    u and r come from running the runtime's own pre-filter over each pair's frames."""
    us, rs, ys = [], [], []
    names = w.inputs
    a = w.arrays
    for p in pairs:
        pre = OneEuro(names=names, min_cutoff=a["min_cutoff"].tolist(),
                      beta=a["beta"].tolist(), d_cutoff=a["d_cutoff"].tolist())  # fmt: skip
        x = p.tracked.arkit(names)[0]
        y = p.truth.arkit(names)[0]
        u = np.full_like(x, np.nan)
        valid = ~np.isnan(x).all(axis=1)
        prefilter = w.config["prefilter"]
        for i in np.flatnonzero(valid):
            xi = np.nan_to_num(x[i])
            u[i] = pre.step(xi, p.tracked.times[i]) if prefilter else xi
        r = np.fmin.accumulate(np.where(valid[:, None], u, np.inf), axis=0)
        ok = valid & ~np.isnan(y).any(axis=1)
        us.append(u[ok])
        rs.append(r[ok])
        ys.append(y[ok])
    return np.concatenate(us), np.concatenate(rs), np.concatenate(ys)


def ridge(u: np.ndarray, y: np.ndarray, lam: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """(A (M, K), c (M,)) minimising |A u + c - y|^2 + lam s |A|^2, s the mean of diag(u'u)
    (the shrinkage in proportion to the data, whatever its length and levels)."""
    f, k = u.shape
    x = np.concatenate([u, np.ones((f, 1))], axis=1)
    gram = x.T @ x
    reg = lam * float(np.mean(np.diag(gram)[:k])) * np.eye(k + 1)
    reg[-1, -1] = 0.0  # the offset is not shrunk
    sol = np.linalg.solve(gram + reg, x.T @ y)  # (K+1, M)
    return sol[:-1].T, sol[-1]


def fit_ridge(train: Sequence[Pair], lam: float = 1e-4) -> MapWeights:
    """The per-channel ridge baseline: a linear map over all raw inputs, no filter."""
    names = channels(train)
    w = blank(names, 0, PREFILTERS[0], rest=False, prefilter=False)
    u, _, y = features(w, train)
    a, c = ridge(u, y, lam)
    w.arrays["a"], w.arrays["c"] = a, c
    w.config.update(fitted="ridge", lam=lam, frames=len(u))
    return w


def fit(
    train: Sequence[Pair],
    val: Sequence[Pair],
    hidden: int = 64,
    rest: bool = True,
    epochs: int = 60,
    seed: int = 0,
    prefilters: Sequence[tuple[float, float, float]] = PREFILTERS,
    report: Report | None = None,
) -> MapWeights:
    """The tracker map with the best validation MSE over ``prefilters``."""
    report = report or (lambda _e: None)
    names = channels(train)
    best: tuple[float, MapWeights] | None = None
    for pre in prefilters:
        w = blank(names, hidden, pre, rest)
        u, r, y = features(w, train)
        vu, vr, vy = features(w, val) if val else (u, r, y)
        _fit_one(w, u, r, y, vu, vr, vy, epochs, seed, report)
        score = float(np.mean((_predict(w, vu, vr) - vy) ** 2))
        report({"event": "prefilter", "pre": pre, "val_mse": score})
        if best is None or score < best[0]:
            best = (score, w)
    assert best is not None
    best[1].config.update(val_mse=best[0], frames=int(len(u)))
    return best[1]


def _predict(w: MapWeights, u: np.ndarray, r: np.ndarray) -> np.ndarray:
    a = w.arrays
    lin = u @ a["a"].T + a["c"]
    if w.config["hidden"]:
        rest = (u - r) if w.config["rest"] else np.zeros_like(u)
        z = (np.concatenate([u, rest], axis=1) - a["mu"]) / a["sd"]
        lin = lin + np.tanh(z @ a["w1"].T + a["b1"]) @ a["w2"].T + a["b2"]
    return np.clip(lin, 0.0, 1.0)


def _fit_one(w, u, r, y, vu, vr, vy, epochs, seed, report) -> None:
    a = w.arrays
    a["a"], a["c"] = ridge(u, y)
    if not w.config["hidden"]:
        return
    rest_u = (u - r) if w.config["rest"] else np.zeros_like(u)
    z = np.concatenate([u, rest_u], axis=1)
    a["mu"], a["sd"] = z.mean(0), np.maximum(z.std(0), 1e-3)
    torch.manual_seed(seed)
    k, h = u.shape[1], int(w.config["hidden"])
    net = torch.nn.Sequential(torch.nn.Linear(2 * k, h), torch.nn.Tanh(), torch.nn.Linear(h, k))
    lin = torch.nn.Linear(k, k)
    with torch.no_grad():
        torch.nn.init.zeros_(net[2].weight)
        torch.nn.init.zeros_(net[2].bias)
        lin.weight.copy_(torch.tensor(a["a"]))
        lin.bias.copy_(torch.tensor(a["c"]))
    params = [*net.parameters(), *lin.parameters()]
    opt = torch.optim.Adam(params, lr=3e-3, weight_decay=1e-5)

    def tensors(uu, rr):
        rr_u = (uu - rr) if w.config["rest"] else np.zeros_like(uu)
        zz = (np.concatenate([uu, rr_u], axis=1) - a["mu"]) / a["sd"]
        return torch.tensor(zz, dtype=torch.float32), torch.tensor(uu, dtype=torch.float32)

    zt, ut = tensors(u, r)
    yt = torch.tensor(y, dtype=torch.float32)
    vz, vu_t = tensors(vu, vr)
    vyt = torch.tensor(vy, dtype=torch.float32)
    gen = torch.Generator().manual_seed(seed)
    best, best_state, bad = float("inf"), None, 0
    for epoch in range(epochs):
        order = torch.randperm(len(zt), generator=gen)
        for i in range(0, len(order), 512):
            idx = order[i : i + 512]
            pred = torch.clamp(net(zt[idx]) + lin(ut[idx]), 0.0, 1.0)
            loss = torch.mean((pred - yt[idx]) ** 2)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
        with torch.no_grad():
            val = float(torch.mean((torch.clamp(net(vz) + lin(vu_t), 0, 1) - vyt) ** 2))
        report({"event": "epoch", "epoch": epoch, "val_mse": val})
        if val < best - 1e-7:
            best, bad = val, 0
            best_state = [p.detach().clone() for p in params]
        else:
            bad += 1
            if bad >= 8:
                break
    with torch.no_grad():
        for p, s in zip(params, best_state or [p.detach() for p in params], strict=True):
            p.copy_(s)
    a["w1"] = net[0].weight.detach().double().numpy()
    a["b1"] = net[0].bias.detach().double().numpy()
    a["w2"] = net[2].weight.detach().double().numpy()
    a["b2"] = net[2].bias.detach().double().numpy()
    a["a"] = lin.weight.detach().double().numpy()
    a["c"] = lin.bias.detach().double().numpy()
