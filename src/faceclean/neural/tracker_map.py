"""Fitting a tracker map (learned/tracker_map.py) on (tracked, truth) pairs.

The map is memoryless given its causal features (the pre-filtered input u and the resting
level r), and those do not depend on the map's weights: they are computed once per pair
with the runtime's own One Euro (so training sees what the cleaner computes), and the map
is fitted frame by frame. The linear part ``A u + B (u - r) + c`` by ridge (closed form);
an optional hidden layer on top with Adam, early-stopped. The pre-filter and the ridge
shrinkage are chosen on validation pairs (performances no training pair comes from) by
MSE, with a price on jitter beyond ``JITTER_BUDGET`` x the truth's, and with them how
much of each output's detail (its own input's x - u) it keeps (``DETAILS``: the detail
gains are fitted unshrunk, then scaled). The output deadband
(``DEADBAND``) is a fixed setting, in place while every candidate is scored. Then the
blink lift (blink_lift.py, on this module's folds): its knee chosen leaving each source
out as well, with a price on blink closure outside ``CLOSURE_BAND``, its gains fitted on
the performances.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
import torch

from faceclean.datasets.paired import Pair, performances
from faceclean.learned.map_weights import MAX_DETAIL, MapWeights
from faceclean.neural import blink_lift, map_groups
from faceclean.neural.blink_lift import CLOSURE_BAND as CLOSURE_BAND  # the fit's settings
from faceclean.neural.blink_lift import KNEES, TOPS
from faceclean.neural.map_features import (
    Feature,
    blank,
    channels,
    features,
    own_inputs,
    predict,
    score,
    set_linear,
)
from faceclean.neural.map_groups import at_rest

# (min_cutoff Hz, beta, d_cutoff Hz) pre-filter candidates (None: no pre-filter). The
# (1-0.5 Hz, beta 5-20) ones hold a face at rest hard and open up when it moves (the speed
# estimate itself at 4 Hz); the last four open up at once (beta 20-50), which leaves
# MediaPipe's own lag nearly as it is (docs/MODEL.md). Across sources many tie on MSE, so
# the choice among them is by lag within the jitter budget (TIE).
PREFILTERS: tuple[tuple[float, float, float] | None, ...] = (
    None, (8.0, 1.0, 1.0), (6.0, 0.5, 1.0), (4.0, 1.0, 1.0), (2.0, 0.5, 1.0),
    (1.0, 0.3, 1.0), (1.0, 5.0, 4.0), (0.5, 5.0, 4.0), (1.0, 10.0, 4.0), (0.5, 10.0, 4.0),
    (1.0, 20.0, 4.0), (4.0, 20.0, 4.0), (8.0, 20.0, 8.0), (2.0, 50.0, 4.0),
    (4.0, 50.0, 8.0))  # fmt: skip
LAMBDAS = (1e-2, 1e-1, 3e-1, 1.0)  # ridge shrinkage, relative to the inputs' mean square
LIGHT = (4.0, 1.0, 1.0)  # the pre-filter settings a map without one stores (unused)
JITTER_BUDGET = 1.5  # a candidate whose jitter is over this x the truth's pays for it
TIE = 0.005  # cross-validated scores this close to the best (relative) count as equal
# The output deadband, weight units: 1 % of a channel's range, below what shows on a face,
# and over 10x the mean frame-to-frame change MediaPipe's noise on a still face leaves in
# the map's output (0.0007, docs/MODEL.md); it holds a face at rest, so the tie among
# pre-filters can go to lag.
DEADBAND = 0.01
# How much of the least-squares detail gain each candidate keeps (0: none; the model's
# ``detail_scale``, which a user may change: TrackerMap's ``detail``). The gain is shrunk
# by its own scale only: the detail is small beside the levels, and a shrinkage scaled to
# the inputs' mean square took it to 0 (docs/MODEL.md); the scale is how the choice
# trades lag against jitter.
DETAILS = (0.0, 0.25, 0.5, 0.75, 1.0)
DETAIL_SHRINK = 0.01  # the detail gain's ridge, relative to the detail's own mean square
Report = Callable[[dict[str, Any]], None]


def _stack(feats: Sequence[Feature], rest: bool, detail: bool = False) -> tuple[np.ndarray, ...]:
    """(inputs (F, D): u, and u - r when ``rest``, and the detail e when ``detail``;
    truth (F, K))."""
    z = [np.concatenate([f.u, f.u - f.r] if rest else [f.u], axis=1) for f in feats]
    if detail:
        z = [np.concatenate([zi, f.e], axis=1) for zi, f in zip(z, feats, strict=True)]
    return np.concatenate(z), np.concatenate([f.y for f in feats])


def ridge(u: np.ndarray, y: np.ndarray, lam: float = 1e-2) -> tuple[np.ndarray, np.ndarray]:
    """(A (M, D), c (M,)) minimising |A u + c - y|^2 + lam s |A|^2, s the mean of diag(u'u)
    (the shrinkage in proportion to the data, whatever its length and levels)."""
    return _solve(*_moments(u, y), lam)


def _moments(u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x'x (D+1, D+1), x'y (D+1, M)) of x = [u, 1]: what a ridge fit needs of the data."""
    x = np.concatenate([u, np.ones((len(u), 1))], axis=1)
    return x.T @ x, x.T @ y


def _solve_detail(gram: np.ndarray, xty: np.ndarray, lam: float, own: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """(A (M, D), c (M,), d (M,)) from the moments of [z, e, 1] (D + K + 1 columns): per
    output j, ridge over z and its own input's detail e[own[j]] (own -1: none), z shrunk
    as ``_solve`` shrinks it, the detail by DETAIL_SHRINK of its own mean square only (a
    zero column, a map without a pre-filter, gets d = 0); d within [0, MAX_DETAIL] (a
    negative gain would turn a channel's own timing round; on MediaPipe's near-silent
    channels the fit gave some, and clipped they score the same). The runtime scales d by
    the config's ``detail_scale``."""
    m, k = xty.shape[1], len(own)
    dim = len(gram) - 1 - k
    keep = np.r_[0:dim, dim + k]  # z and the offset
    shrink = lam * float(np.mean(np.diag(gram)[:dim]))
    coef, c, d = np.zeros((m, dim)), np.zeros(m), np.zeros(m)
    for j in range(m):
        idx = np.r_[0:dim, dim + own[j], dim + k] if own[j] >= 0 else keep
        reg = np.zeros(len(idx))
        reg[:dim] = shrink
        if own[j] >= 0:
            reg[dim] = DETAIL_SHRINK * gram[dim + own[j], dim + own[j]] + 1e-12 * shrink
        sol = np.linalg.solve(gram[np.ix_(idx, idx)] + np.diag(reg), xty[idx, j])
        coef[j], c[j] = sol[:dim], sol[-1]
        d[j] = np.clip(sol[dim], 0.0, MAX_DETAIL) if own[j] >= 0 else 0.0
    return coef, c, d


def _fold_solve(w: MapWeights, gram: np.ndarray, xty: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The linear part from moments of [z, e, 1]: per output group as ``w``'s chosen
    structure says (map_groups.py), else one ridge over every input (``_solve_detail``)."""
    if "structure" in w.config:
        choice = {g: (k, float(lam)) for g, (k, lam) in w.config["structure"].items()}
        return map_groups.solve(gram, xty, w.inputs, choice)
    return _solve_detail(gram, xty, w.config["lam"], own_inputs(w))


def _solve(gram: np.ndarray, xty: np.ndarray, lam: float) -> tuple[np.ndarray, np.ndarray]:
    k = len(gram) - 1
    reg = lam * float(np.mean(np.diag(gram)[:k])) * np.eye(k + 1)
    reg[-1, -1] = 0.0  # the offset is not shrunk
    sol = np.linalg.solve(gram + reg, xty)  # (D+1, M)
    return sol[:-1].T, sol[-1]


def fold_key(p: Pair, families: bool) -> str:
    """The fold a pair is scored in: its source, or with ``families`` its appearance family
    and source ("photo/neurosync"): a fold held out leaves both out (``left_out``)."""
    return f"{p.family}/{p.group}" if families else p.group


def left_out(p: Pair, key: str) -> bool:
    """Whether ``key``'s fold keeps ``p`` out of its training: the same source, or (a
    family fold) the same look."""
    family, _, group = key.rpartition("/")
    return p.group == group or (bool(family) and p.family == family)


def _sources(pool: Sequence[Pair]) -> tuple[list[str], list[str | None]]:
    """(the folds scored, sorted; each pair's fold, None for a clip: never scored). With
    more than one appearance family in ``pool`` a fold is a (family, source) cell, left out
    both ways at once; else a source."""
    perf = {id(p) for p in performances(pool)}
    many = len({p.family for p in pool}) > 1
    scored = [fold_key(p, many) if id(p) in perf else None for p in pool]
    return sorted({s for s in scored if s is not None}), scored


def _raw_mse(pool, names, rest: bool, scored) -> dict[str, float]:
    """Raw MSE per source over its performances: what a fold's MSE is a ratio to."""
    raw = blank(names, 0, LIGHT, rest, prefilter=False)
    feats = features(raw, pool)
    return {g: score(raw, [f for f, s in zip(feats, scored, strict=True) if s == g])[0]
            for g in sorted({s for s in scored if s is not None})}  # fmt: skip


def _folds(pool, feats, rest: bool, scored) -> dict[str, tuple]:
    """source -> (x'x, x'y of every other source's pairs and clips, its performances'
    features): from the summed moments (of [z, e, 1]: ``_solve_detail``), so a fold costs
    one ridge solve."""
    moments = [_moments(*_stack([f], rest, detail=True)) for f in feats]  # per pair
    total = [sum(m[i] for m in moments) for i in (0, 1)]
    folds = {}
    for g in sorted({s for s in scored if s is not None}):
        out = [i for i, p in enumerate(pool) if left_out(p, g)]
        folds[g] = (*(total[j] - sum(moments[i][j] for i in out) for j in (0, 1)),
                    [feats[i] for i in out if scored[i] == g])  # fmt: skip
    return folds


def fit_ridge(
    train: Sequence[Pair], val: Sequence[Pair] = (), lams: Sequence[float] = LAMBDAS
) -> MapWeights:
    """The per-channel ridge baseline: a linear map over all raw inputs, no filter, no rest
    level; its shrinkage chosen on ``val`` (on ``train`` without it)."""
    names = channels(train)
    w = blank(names, 0, LIGHT, rest=False, prefilter=False)
    feats = features(w, train)
    vfeats = features(w, performances(val)) if performances(val) else feats
    z, y = _stack(feats, False)
    best = None
    for lam in lams:
        set_linear(w, *ridge(z, y, lam))
        mse = score(w, vfeats)[0]
        if best is None or mse < best[0]:
            best = (mse, lam)
    all_feats = features(w, [*train, *val])  # the chosen shrinkage, on every pair given
    set_linear(w, *ridge(*_stack(all_feats, False), best[1]))
    w.config.update(fitted="ridge", lam=best[1], frames=int(sum(len(f[0]) for f in all_feats)))
    return w


def fit(
    train: Sequence[Pair],
    val: Sequence[Pair],
    hidden: int = 0,
    rest: bool = True,
    epochs: int = 60,
    seed: int = 0,
    prefilters: Sequence[tuple[float, float, float] | None] = PREFILTERS,
    lams: Sequence[float] = LAMBDAS,
    report: Report | None = None,
    refit: bool = True,
    cv: bool = True,
    deadband: float = DEADBAND,
    knees: Sequence[float | None] = KNEES,
    details: Sequence[float] = DETAILS,
    structured: bool = False,
) -> MapWeights:
    """The tracker map: for each pre-filter (None: none) and shrinkage, the linear part by
    ridge on the training pairs (and the hidden layer when ``hidden`` > 0), scored on
    ``val`` by MSE x (1 + jitter over JITTER_BUDGET x the truth's, when over): the best,
    refitted on ``train`` and ``val`` together when ``refit`` (a linear map only).

    ``cv`` (a linear map, three sources or more among ``train`` and ``val``): the choice
    is made leaving one source out in turn instead (``_cross_validate``), not on ``val``
    alone: one source's faces are too few to tell pre-filters apart; and so is the blink
    lift's knee among ``knees`` (``_choose_lift``; ``(None,)``: no lift) and the detail's
    scale among ``details``. Without ``cv`` the map has no detail. ``structured`` (with
    ``cv`` and ``rest``): which inputs each output group reads is chosen on the folds too,
    every fit shrunk toward the tracker's own channel (map_groups.py)."""
    report = report or (lambda _e: None)
    torch.set_num_threads(1)  # a tiny net: more threads only contend
    names = channels(train)
    pool = [*train, *val]
    if cv and not hidden and len({p.group for p in performances(pool)}) >= 3:
        w = _cross_validate(pool, names, prefilters, lams, rest, report, deadband, details)
        feats = features(w, pool)
        if refit:
            gram, xty = _moments(*_stack(feats, rest, detail=True))
            if structured and rest:  # per output group, on the folds (map_groups.py)
                _, scored = _sources(pool)
                folds = _folds(pool, feats, rest, scored)
                choice = map_groups.choose(w, folds, predict, set_linear, report)
                w.config["structure"] = {g: [k, lam] for g, (k, lam) in choice.items()}
            set_linear(w, *_fold_solve(w, gram, xty))
            _choose_lift(w, pool, rest, knees, report)
        w.config.update(frames=int(sum(len(f[0]) for f in feats)))
        return w
    best: tuple[float, MapWeights] | None = None
    for pre in prefilters:
        w = blank(names, hidden, pre or LIGHT, rest, prefilter=pre is not None,
                  deadband=deadband)  # fmt: skip
        feats = features(w, train)
        vfeats = features(w, performances(val)) if performances(val) else feats
        z, y = _stack(feats, rest)
        for lam in lams:
            set_linear(w, *ridge(z, y, lam))
            if hidden:
                _fit_hidden(w, feats, vfeats, epochs, seed, report)
            mse, jit = score(w, vfeats)
            price = mse * (1.0 + max(0.0, jit / JITTER_BUDGET - 1.0))
            report({"event": "candidate", "pre": pre, "lam": lam, "val_mse": mse, "jitter": jit})
            if best is None or price < best[0]:
                best = (price, MapWeights(dict(w.config, lam=lam, val_mse=mse, val_jitter=jit),
                                          {k: v.copy() for k, v in w.arrays.items()}))  # fmt: skip
    assert best is not None
    w = best[1]
    if refit and val and not hidden:  # the chosen settings, fitted on every pair given
        set_linear(w, *ridge(*_stack(features(w, [*train, *val]), rest), w.config["lam"]))
    w.config.update(frames=int(sum(len(f[0]) for f in features(w, [*train, *val]))))
    return w


class Candidate(NamedTuple):
    """One (pre-filter, shrinkage, detail scale) scored leaving each source out."""

    score: float  # mean MSE x raw over the folds, x the jitter's price
    jitter: float  # mean jitter ratio to the truth's over the folds
    worst: float  # the worst fold's jitter ratio
    pre: tuple[float, float, float] | None  # the pre-filter (None: none)
    lam: float
    detail: float  # the detail scale
    config: dict[str, Any]  # the config of weights with this choice


def _cross_validate(
    pool, names, prefilters, lams, rest: bool, report: Report, deadband: float = 0.0,
    details: Sequence[float] = DETAILS,
) -> MapWeights:  # fmt: skip
    """The pre-filter, shrinkage and detail scale (``details``; a map without a pre-filter
    has no detail) that score best leaving one source out: for each
    source, the ridge fitted on every other source's pairs and clips, scored on its own
    performances by MSE as x raw (each source alike, whatever its error's size), the mean
    over sources x (1 + jitter over JITTER_BUDGET x the truth's, when over). Of the
    candidates within TIE of the best score (a difference that small is noise over a few
    sources) whose jitter is within JITTER_BUDGET on every source left out, the one with
    the least lag is taken; when none is, the smoothest (every source, not their mean: a
    mean within budget let a light pre-filter leave 6x the truth's jitter on a noisier
    source; docs/MODEL.md). The weights returned hold the choice (their linear part still
    to be fitted)."""
    groups, scored = _sources(pool)
    raw_mse = _raw_mse(pool, names, rest, scored)

    def folded(pre):  # (weights to fill, each output's own input, the folds) at pre
        w = blank(names, 0, pre or LIGHT, rest, prefilter=pre is not None, deadband=deadband)
        return w, own_inputs(w), _folds(pool, features(w, pool), rest, scored)

    # Pass 1, every candidate.
    found: list[Candidate] = []
    for pre in prefilters:
        w, own, folds = folded(pre)
        solved = {(g, lam): _solve_detail(gram, xty, lam, own)
                  for lam in lams for g, (gram, xty, _) in folds.items()}  # fmt: skip
        for lam, kappa in [(lam, kappa) for lam in lams for kappa in details
                           if pre is not None or kappa == 0.0]:  # fmt: skip
            trial = MapWeights(dict(w.config, detail_scale=kappa), w.arrays)  # one fit, scaled
            ratios, jits = [], []
            for g, (_, _, held) in folds.items():
                if at_rest(g):
                    continue
                set_linear(trial, *solved[g, lam])
                mse, jit = score(trial, held)
                ratios.append(mse / max(raw_mse[g], 1e-12))  # (a perfect tracker: raw 0)
                jits.append(jit)
            known = np.array(jits)[~np.isnan(jits)]  # NaN: too short to tell
            ratio, jit = float(np.mean(ratios)), float(known.mean()) if known.size else 0.0
            worst = float(known.max()) if known.size else 0.0
            price = ratio * (1.0 + max(0.0, jit / JITTER_BUDGET - 1.0))
            report({"event": "candidate", "pre": pre, "lam": lam, "detail": kappa,
                    "val_mse": ratio, "jitter": jit, "worst_jitter": worst,
                    "cv": len(groups)})  # fmt: skip
            config = dict(trial.config, lam=lam, val_mse=ratio, val_jitter=jit,
                          selected="leave one source out: " + ", ".join(groups))  # fmt: skip
            found.append(Candidate(price, jit, worst, pre, lam, kappa, config))
    top = min(c.score for c in found)
    tied = [c for c in found if c.score <= top * (1.0 + TIE)]
    calm = [c for c in tied if c.worst <= JITTER_BUDGET]
    if not calm:
        chosen = min(tied, key=lambda c: c.jitter)
        return MapWeights(chosen.config, folded(chosen.pre)[0].arrays)
    # Pass 2, the lag of the calm ones only (the costliest measure: ~80 % of a score).
    best: MapWeights | None = None
    least = float("inf")
    for pre in dict.fromkeys(c.pre for c in calm):
        w, own, folds = folded(pre)
        for c in [c for c in calm if c.pre == pre]:
            trial = MapWeights(c.config, w.arrays)  # the candidate's detail scale
            lags = []
            for g, (gram, xty, held) in folds.items():
                if at_rest(g):
                    continue
                set_linear(trial, *_solve_detail(gram, xty, c.lam, own))
                lags.append(score(trial, held, lag=True)[2])
            lag = float(np.nanmean(lags)) if np.isfinite(lags).any() else 0.0
            report({"event": "candidate_lag", "pre": pre, "lam": c.lam, "detail": c.detail,
                    "lag_ms": lag, "cv": len(groups)})  # fmt: skip
            if best is None or lag < least:
                arrays = {k: v.copy() for k, v in w.arrays.items()}
                best, least = MapWeights(dict(c.config, val_lag_ms=lag), arrays), lag
    assert best is not None
    return best


_lift_gains, _set_lift = blink_lift.gains, blink_lift.set_gains  # as the tests reach them


def _choose_lift(w: MapWeights, pool, rest: bool, knees, report: Report, tops=TOPS) -> None:
    """Sets ``w``'s blink lift (blink_lift.choose): the knee (None: no lift) and top
    (``tops``) chosen leaving one source out, on the folds ``_cross_validate`` scores
    (the linear part fitted on every other source at ``w``'s pre-filter and shrinkage, the
    gains on their performances); its gains then fitted on every performance in
    ``pool``. The linear part of ``w`` is kept as it is."""
    blink_lift.clear(w)
    groups, scored = _sources(pool)
    feats = features(w, pool)
    performed = [f for f, s in zip(feats, scored, strict=True) if s is not None]
    if tuple(knees) == (None,) or len(groups) < 3 or not any(_lift_gains(w, performed, 0.0)):
        return  # nothing to lift, or too few sources to choose
    raw_mse = _raw_mse(pool, w.inputs, rest, scored)
    folds = {}
    for g, (gram, xty, held) in _folds(pool, feats, rest, scored).items():
        train = [f for f, s, p in zip(feats, scored, pool, strict=True)
                 if s is not None and not left_out(p, g)]  # fmt: skip
        folds[g] = blink_lift.Fold(_fold_solve(w, gram, xty), train, held, raw_mse[g])
    blink_lift.choose(w, performed, folds, score, set_linear, report, JITTER_BUDGET, knees, tops)


def _fit_hidden(w: MapWeights, feats, vfeats, epochs: int, seed: int, report: Report) -> None:
    """The hidden layer on top of the fitted linear part (Adam, early stopped on ``vfeats``)."""
    a = w.arrays
    k, h = len(w.inputs), int(w.config["hidden"])

    def tensors(fs):
        u = np.concatenate([f.u for f in fs])
        r = np.concatenate([f.r for f in fs])
        z = np.concatenate([u, u - r if w.config["rest"] else np.zeros_like(u)], axis=1)
        return z, torch.tensor(np.concatenate([f.y for f in fs]), dtype=torch.float32)

    z, yt = tensors(feats)
    vz, vyt = tensors(vfeats)
    a["mu"], a["sd"] = z.mean(0), np.maximum(z.std(0), 1e-3)
    lin_w = np.concatenate([a["a"], a["b"]], axis=1)  # (K, 2K) over [u, u - r]
    zt = torch.tensor((z - a["mu"]) / a["sd"], dtype=torch.float32)
    vzt = torch.tensor((vz - a["mu"]) / a["sd"], dtype=torch.float32)
    raw, vraw = torch.tensor(z, dtype=torch.float32), torch.tensor(vz, dtype=torch.float32)
    torch.manual_seed(seed)
    net = torch.nn.Sequential(torch.nn.Linear(2 * k, h), torch.nn.Tanh(), torch.nn.Linear(h, k))
    lin = torch.nn.Linear(2 * k, k)
    with torch.no_grad():
        torch.nn.init.zeros_(net[2].weight)
        torch.nn.init.zeros_(net[2].bias)
        lin.weight.copy_(torch.tensor(lin_w))
        lin.bias.copy_(torch.tensor(a["c"]))
    params = [*net.parameters(), *lin.parameters()]
    opt = torch.optim.Adam(params, lr=3e-3, weight_decay=1e-5)
    gen = torch.Generator().manual_seed(seed)
    best, best_state, bad = float("inf"), [p.detach().clone() for p in params], 0
    for epoch in range(epochs):
        order = torch.randperm(len(zt), generator=gen)
        for i in range(0, len(order), 512):
            idx = order[i : i + 512]
            pred = torch.clamp(net(zt[idx]) + lin(raw[idx]), 0.0, 1.0)
            loss = torch.mean((pred - yt[idx]) ** 2)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
        with torch.no_grad():
            val = float(torch.mean((torch.clamp(net(vzt) + lin(vraw), 0, 1) - vyt) ** 2))
        report({"event": "epoch", "epoch": epoch, "val_mse": val})
        if val < best - 1e-7:
            best, bad = val, 0
            best_state = [p.detach().clone() for p in params]
        else:
            bad += 1
            if bad >= 8:
                break
    with torch.no_grad():
        for p, s in zip(params, best_state, strict=True):
            p.copy_(s)
    a["w1"] = net[0].weight.detach().double().numpy()
    a["b1"] = net[0].bias.detach().double().numpy()
    a["w2"] = net[2].weight.detach().double().numpy()
    a["b2"] = net[2].bias.detach().double().numpy()
    coef = lin.weight.detach().double().numpy()
    a["a"], a["b"], a["c"] = coef[:, :k], coef[:, k:], lin.bias.detach().double().numpy()
