"""A map's candidates scored on folds that leave a look and a source out at once.

Two accuracies: the MSE x raw pooled over each fold's performances (meaned over the folds;
the shipped map's choice), and the *typical* MSE x raw, the geometric mean over the folds'
performances of each one's own MSE x raw (one face performing one take counts as one).
Pooled, the takes that move a channel most carry its score: on the appearance families'
folds the thirteenth round's map pooled the jaw at 0.87x raw over the real performances
while it was worse than raw on half of them one by one (median 1.01x, one in ten over 4x).
Chosen on the typical MSE, with another group's neighbours shrunk harder, the real jaw
gained and the painted faces' lids went above raw held out (docs/MODEL.md, fourteenth
round): map_rises.fit's ``judge="typical"``, not its default."""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from faceclean.datasets.paired import Pair, performances
from faceclean.neural import map_features, tracker_map
from faceclean.neural.map_groups import SELECT, at_rest, group_of
from faceclean.neural.map_groups import real as is_real

SETTLE_S = 0.5  # s into a neutral hold before it is judged


class Scored(NamedTuple):
    """One candidate's scores over the folds (``cross_validate``)."""

    mse: float  # mean over the folds of the MSE x raw pooled over each fold's performances
    jitter: float  # their mean jitter x the truth's
    lag: float  # their mean lag, ms
    per_group: dict[str, dict[str, float]]  # group -> family -> MSE x raw
    own: dict[str, dict[str, float]]  # the same for every output its own rise (gain 1)
    off: float  # the worst channel's mean |y - truth| on the neutral holds after SETTLE_S
    real: np.ndarray | None = None  # (3, M) squared error of the map, its own rise, raw per
    # output, summed over the folds' real performances (None: no real performance)
    typical: float = float("nan")  # geometric mean of each performance's MSE x raw

    @property
    def real_mse(self) -> float:
        """MSE x raw pooled over the folds' real performances (NaN: none)."""
        if self.real is None:
            return float("nan")
        return float(self.real[0].sum() / max(self.real[2].sum(), 1e-12))


def folds(pairs: Sequence[Pair]) -> dict[str, list[int]]:
    """fold key -> indices of the pairs it scores; more than one family: a (family, source)
    cell left out both ways (tracker_map.fold_key), else a source. Fewer than three
    sources: none (nothing to choose on)."""
    many = len({p.family for p in pairs}) > 1
    perf = {id(p) for p in performances(pairs)}
    out: dict[str, list[int]] = {}
    for i, p in enumerate(pairs):
        if id(p) in perf:
            out.setdefault(tracker_map.fold_key(p, many), []).append(i)
    return out if len({k.rpartition("/")[2] for k in out}) >= 3 else {}


def cross_validate(w, feats, folds, fits) -> Scored:
    """The runtime's output (map_features.predict, ``w``'s deadband and detail included) of
    each fold's fit (``fits``: fold key -> map_features.set_linear's arguments) on the
    fold's pairs, scored (``Scored``)."""
    from faceclean.evaluation.metrics import jitter_ratio, lag_ms  # numpy only

    names = w.inputs
    gi = np.array([list(SELECT).index(group_of(n)) for n in names])
    ratios, sse, jitter, lags = [], {}, [], []
    logs: list[float] = []  # log MSE x raw of each performance
    dev, frames = np.zeros(len(names)), 0
    real = np.zeros((3, len(names)))  # map, own rise, raw: per output, real performances
    for key, linear in fits.items():
        map_features.set_linear(w, *linear)
        fam = key.rpartition("/")[0] or "all"
        s, o, r = (np.zeros(len(SELECT)) for _ in range(3))
        for i in folds[key]:
            f = feats[i]
            pred = map_features.predict(w, f.u, f.r, f.e, f.t)
            if at_rest(key):
                keep = f.t - f.t[0] >= SETTLE_S
                dev += np.abs(pred[keep] - f.y[keep]).sum(0)
                frames += int(keep.sum())
                continue
            own = np.clip(f.u - f.r, 0.0, 1.0)  # every output its own rise
            errors = [((v - f.y) ** 2).sum(0) for v in (pred, own, f.u + f.e)]  # (M,) each
            for acc, e in zip((s, o, r), errors, strict=True):
                np.add.at(acc, gi, e)
            if errors[2].sum() > 0:
                logs.append(np.log(max(errors[0].sum(), 1e-12) / errors[2].sum()))
            if is_real(key):
                real += errors
            if len(f.t) > 3:
                jitter.append(jitter_ratio(f.t, pred, f.y))
                lags.append(lag_ms(f.t, pred, f.y))
        if at_rest(key) or r.sum() <= 0:
            continue
        ratios.append(s.sum() / r.sum())
        for g, group in enumerate(SELECT):
            cell = sse.setdefault(group, {}).setdefault(fam, np.zeros(3))
            cell += (s[g], o[g], r[g])
    per_group = {g: {f: v[0] / max(v[2], 1e-12) for f, v in fam.items()} for g, fam in sse.items()}
    own = {g: {f: v[1] / max(v[2], 1e-12) for f, v in fam.items()} for g, fam in sse.items()}
    off = float((dev / frames).max()) if frames else float("nan")
    mean = lambda v: float(np.nanmean(v)) if np.isfinite(v).any() else float("nan")  # noqa: E731
    typical = float(np.exp(np.mean(logs))) if logs else float("nan")
    return Scored(
        mean(ratios), mean(jitter), mean(lags), per_group, own, off,
        real if real[2].any() else None, typical,
    )  # fmt: skip
