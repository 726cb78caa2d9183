"""Which inputs each output group of a tracker map reads, chosen on looks and sources that
no fit saw.

A map fitted on one renderer's faces learns mixes that hold for those faces only (issue
34: gaze re-mixed by one renderer's eyes; channels the tracker reads as zero lifted to the
training takes' level). Per output j the candidates (``KINDS``), over the causal features
of tracker_map.py (u the pre-filtered input, r its rest so far, e = x - u the detail):

    pass    y_j = u_j                                        the tracker, pre-filtered
    own     y_j = a u_j + b (u_j - r_j) + d e_j               its own input, levelled
    rise    y_j = b (u_j - r_j) + d e_j                       its own rise above rest only
    group   own + sum_k B_jk (u_k - r_k), k in j's group      the neighbours' rises

No offset, and other channels enter only by their rise above rest, 0 on a face at rest: a
face that gives no evidence for a channel gets back its own input (scaled), or 0 for
``rise``, never a training level (an offset, or a mix of other channels' resting
readings). Every fit shrinks toward ``pass``: ridge on y - u_j, the level and rise columns
by ``lam`` x their common mean square, the detail by ``lam`` x its own (as ``lam`` grows,
y_j -> u_j).

The choice, per selection group (``SELECT``: gaze apart from the lids), is the candidate
with the least mean MSE ratio to raw MediaPipe over the folds (tracker_map.py's folds: with
several appearance families, a look and a source left out at once), among those that do
no harm: no worse than raw (``HARM``) averaged over each family's folds, and on the folds'
neutral holds (source ``neutral``) no channel off the truth's rest by more than
``NEUTRAL_TOL`` on average, and on the performances no channel lifted by more than
``NEUTRAL_TOL`` on average above its own input where that input is quiet (its rise under
``QUIET``: no evidence, so no level may come from elsewhere). When none is, ``pass`` (or
the harmless one nearest neutral).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from faceclean.channels import GROUPS
from faceclean.learned.tracker_map import MAX_DETAIL

# (a map over every channel's rise, "all", was a kind too: its gains on the rises of
# unrelated channels, each >= 0, stood in for a training level of channels the tracker
# reads as zero, tests/neural/test_map_groups.py; a channel's group is as far as it reads)
KINDS = ("pass", "own", "rise", "group")
LAMBDAS = (0.01, 0.1, 1.0, 10.0)  # relative to each column's mean square
HARM = 1.0  # a group's MSE over raw, mean over one family's folds, may not pass this
NEUTRAL_TOL = 0.05  # weight units: a channel's mean |output - truth| on a face at rest
SETTLE_S = 0.5  # s into a neutral hold before it is judged (the pre-filter's start)
QUIET = 0.02  # a channel's own rise above rest under which its input gives no evidence
SELECT: dict[str, tuple[str, ...]] = {
    "gaze": tuple(n for n in GROUPS["eyes"] if n.startswith("eyeLook")),
    "lids": tuple(n for n in GROUPS["eyes"] if not n.startswith("eyeLook")),
    **{g: names for g, names in GROUPS.items() if g != "eyes"},
}
Choice = dict[str, tuple[str, float]]  # selection group -> (kind, lam)
Report = Callable[[dict[str, Any]], None]


def group_of(name: str) -> str:
    return next((g for g, names in SELECT.items() if name in names), "mouth")


def columns(names: Sequence[str], kind: str, j: int) -> list[int]:
    """Columns of [u (K), u - r (K), e (K), 1] that output j (input j of the same name)
    reads under ``kind`` (never the offset; ``pass`` reads none)."""
    k = len(names)
    if kind == "pass":
        return []
    if kind == "rise":
        return [k + j, 2 * k + j]
    if kind == "own":
        return [j, k + j, 2 * k + j]
    g = group_of(names[j])
    peers = [i for i, n in enumerate(names) if kind == "all" or group_of(n) == g]
    return [j, *(k + i for i in peers), 2 * k + j]


def solve(gram: np.ndarray, xty: np.ndarray, names: Sequence[str], choice: Choice
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """(coef (M, 2K) over [u, u - r], offset c (M,), detail d (M,)) from the moments of
    [u, u - r, e, 1] (3K + 1 columns; outputs = inputs = ``names``), each output fitted
    as its group's (kind, lam) says (module docstring)."""
    k = len(names)
    coef, c, d = np.zeros((k, 2 * k)), np.zeros(k), np.zeros(k)
    scale = float(np.mean(np.diag(gram)[: 2 * k]))
    for j, name in enumerate(names):
        kind, lam = choice.get(group_of(name), ("pass", 0.0))
        cols = columns(names, kind, j)
        if not cols:
            coef[j, j] = 1.0
            continue
        prior = np.zeros(len(cols))
        if j in cols:
            prior[cols.index(j)] = 1.0  # y_j ~ u_j before any data
        g = gram[np.ix_(cols, cols)]
        # the level and rise columns by lam x their common mean square (a column of tiny
        # readings cannot buy a large gain: that gain would make a training level of
        # noise), the detail by lam x its own (it is small by design)
        reg = np.where(np.array(cols) < 2 * k, lam * scale, lam * np.maximum(np.diag(g), 1e-12))
        rhs = xty[cols, j] - g @ prior
        sol = prior + np.linalg.solve(g + np.diag(reg), rhs)
        for ci, v in zip(cols, sol, strict=True):
            if ci < 2 * k:
                coef[j, ci] = v
            else:
                d[j] = float(np.clip(v, 0.0, MAX_DETAIL))
    return coef, c, d


def candidates() -> list[tuple[str, float]]:
    return [("pass", 0.0)] + [(kind, lam) for kind in KINDS[1:] for lam in LAMBDAS]


NEUTRAL = "neutral"  # the neutral holds' source (synthetic/engine.py)
MADE_UP = ("synthetic", "independent")  # the made-up performers' sources (synthetic/engine.py)


def real(key: str) -> bool:
    """Whether a fold scores real performances (a shared take's source), not made-up
    performers' nor neutral holds."""
    return key.rpartition("/")[2] not in (*MADE_UP, NEUTRAL)


def at_rest(key: str) -> bool:
    """Whether a fold holds the neutral holds (``pairs --neutral``, source ``neutral``):
    judged for keeping a face at rest, never by MSE over raw (raw's error on a face at
    rest is MediaPipe's offset alone: a ratio to it outweighs the takes)."""
    return key.rpartition("/")[2] == NEUTRAL


def choose(w, folds: dict[str, tuple], predict: Callable, set_linear: Callable,
           report: Report | None = None) -> Choice:  # fmt: skip
    """Per selection group the (kind, lam) of the least mean ratio to raw over ``folds``
    (key -> (x'x, x'y without the fold, its held-out features)) among those within HARM
    in every family (module docstring). ``set_linear(w, coef, c, d)`` sets ``w``'s linear
    part while it scores and ``predict(w, u, r, e)`` is the runtime's output on features
    (tracker_map.py's, passed in: that module calls this one)."""
    report = report or (lambda _e: None)
    names = w.inputs
    gi = np.array([list(SELECT).index(group_of(n)) for n in names])
    n_sel = len(SELECT)
    keys = list(folds)
    raw = np.zeros((len(keys), n_sel))  # raw SSE per fold and group
    for f, key in enumerate(keys):
        for feat in folds[key][2]:
            np.add.at(raw[f], gi, (((feat.u + feat.e) - feat.y) ** 2).sum(0))
    cands = candidates()
    sse = np.zeros((len(cands), len(keys), n_sel))
    off = np.zeros((len(cands), n_sel))  # the worst channel's mean |y - truth| at rest
    lift = np.zeros((len(cands), n_sel))  # the worst channel's mean y - u where u is at rest
    for ci, (kind, lam) in enumerate(cands):
        every = {g: (kind, lam) for g in SELECT}
        dev, frames = np.zeros(len(names)), 0
        up, still = np.zeros(len(names)), np.zeros(len(names))
        for f, key in enumerate(keys):
            gram, xty, held = folds[key]
            set_linear(w, *solve(gram, xty, names, every))
            for feat in held:
                pred = predict(w, feat.u, feat.r, feat.e, feat.t)
                np.add.at(sse[ci, f], gi, ((pred - feat.y) ** 2).sum(0))
                quiet = (feat.u - feat.r) < QUIET  # no evidence on the channel's own input
                up += np.where(quiet, pred - feat.u, 0.0).sum(0)
                still += quiet.sum(0)
                if at_rest(key):
                    keep = feat.t - feat.t[0] >= SETTLE_S
                    dev += np.abs(pred[keep] - feat.y[keep]).sum(0)
                    frames += int(keep.sum())
        for g in range(n_sel):
            if frames:
                off[ci, g] = (dev / frames)[gi == g].max(initial=0.0)
            lift[ci, g] = (up / np.maximum(still, 1))[gi == g].max(initial=0.0)
    # performances only: a neutral hold's raw error is MediaPipe's offset alone, and a
    # ratio to it would outweigh every take (the holds judge the rest, below)
    ok = (raw > 1e-9) & ~np.array([at_rest(k) for k in keys])[:, None]
    ratio = np.where(ok, sse / np.maximum(raw, 1e-12), np.nan)  # (cands, folds, groups)
    families = sorted({k.rpartition("/")[0] for k in keys})
    fam_of = np.array([families.index(k.rpartition("/")[0]) for k in keys])
    choice: Choice = {}
    for g, group in enumerate(SELECT):
        best, best_score = None, np.inf
        nearest, nearest_off = ("pass", 0.0), off[0, g]  # the harmless one nearest neutral
        for ci, cand in enumerate(cands):
            r = ratio[ci, :, g]
            if not np.isfinite(r).any():
                continue
            worst = max(np.nanmean(r[fam_of == i]) for i in range(len(families))
                        if np.isfinite(r[fam_of == i]).any())  # fmt: skip
            score = float(np.nanmean(r))
            report({"event": "structure", "group": group, "kind": cand[0], "lam": cand[1],
                    "val_mse": score, "worst_family": float(worst),
                    "neutral_off": float(off[ci, g])})  # fmt: skip
            if worst > HARM and cand[0] != "pass":
                continue
            if lift[ci, g] > NEUTRAL_TOL:  # a level with no evidence: a training mean
                continue
            if off[ci, g] < nearest_off:
                nearest, nearest_off = cand, off[ci, g]
            if off[ci, g] <= NEUTRAL_TOL and score < best_score:
                best, best_score = cand, score
        choice[group] = best or nearest
    return choice
