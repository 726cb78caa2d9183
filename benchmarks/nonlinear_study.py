"""Does a nonlinear term over the rises carry to a look and a source no fit saw? (issue 34,
twentieth round; docs/MODEL.md)

MediaPipe reads many channels through a curve, not a gain: on the guided benchmark's faces
a smile under 0.3 reads 0 on painted and dressed faces, jawOpen flattens at 0.8 from 0.6
on photographed ones, a photographed eye's look up reads lower at 0.8 than at 0.4
(docs/CALIBRATION.md, "Shrunk by group"). The map over rises is linear. This study adds,
on top of its linear part (neural/map_rises.py ``solve``, the shipped shrinkage 0.01 and
rest), a second stage fitted on the linear part's residual, zero on a face at rest:

- ``hinge``: each output a curve of its own input's rise, sum_k c_k max(z - knot_k, 0);
- ``boost``: each output a gradient-boosted function of every rise (scikit-learn's
  HistGradientBoostingRegressor), minus its value at rest; fitted on every training
  performance, or on the real ones alone (``--real``).

Every fold leaves one appearance family and one performance source out at once, as the
appearance table does (evaluation/family_eval.py); scored on the held-out pairs as MSE x
raw, before any band (the linear part clipped to [0, 1], against it plus the term), over
every performance, the real ones (the shared takes) and the made-up ones.

    .venv/bin/python benchmarks/nonlinear_study.py ~/.cache/faceclean/families-net \\
        --term hinge boost [--real]   # about 10 s and 70 s on 2 cores
"""

from __future__ import annotations

import argparse

import numpy as np
from rest_study import folds

from faceclean.datasets import paired
from faceclean.evaluation.family_eval import NEUTRAL
from faceclean.neural import map_features
from faceclean.neural import map_rises as mr
from faceclean.neural.map_groups import group_of, real

KNOTS = (0.1, 0.25, 0.4)  # weight: where the own-rise curve may bend
RIDGE = 1e-3  # on the curve's coefficients, per frame
PRE = (1.0, 10.0, 2.0)  # the shipped pre-filter (min_cutoff Hz, beta, d_cutoff Hz)
LAM = 0.01  # the shipped shrinkage, weight^2 per frame


def _hinge(z: np.ndarray) -> np.ndarray:
    """(F, K) rises -> (F, K, H) max(z - knot, 0) per knot."""
    return np.stack([np.maximum(z - k, 0.0) for k in KNOTS], axis=-1)


def _target(f) -> np.ndarray:
    """The fit's target: the truth's rise above its own rest (map_rises)."""
    return f.y - np.percentile(f.y, mr.REST_Q, axis=0)


def _hinge_term(train, coef, only):
    """(F, K) rises -> (F, M) correction: per output, a curve of its own rise."""
    m, h = coef.shape[0], len(KNOTS)
    a, b, n = np.zeros((m, h, h)), np.zeros((m, h)), 0
    for f in train:
        z = f.u - f.r
        hz = _hinge(z)
        a += np.einsum("fkh,fkg->khg", hz, hz)
        b += np.einsum("fkh,fk->kh", hz, _target(f) - z @ coef.T)
        n += len(z)
    c = np.stack([np.linalg.solve(a[j] + RIDGE * n * np.eye(h), b[j]) for j in range(m)])
    c[only] = 0.0  # gaze reads its own rise at a gain (OWN_GAIN): no curve
    return lambda z: np.einsum("fkh,kh->fk", _hinge(z), c)


def _boost_term(train, coef, only, step: int = 4):
    """(F, K) rises -> (F, M) correction: per output, boosted trees over every rise."""
    from sklearn.ensemble import HistGradientBoostingRegressor

    z = np.concatenate([(f.u - f.r)[::step] for f in train])
    res = np.concatenate([_target(f)[::step] for f in train]) - z @ coef.T
    models = {}
    for j in range(coef.shape[0]):
        if j not in only:
            models[j] = HistGradientBoostingRegressor(
                max_iter=40, max_leaf_nodes=15, min_samples_leaf=200, l2_regularization=1.0
            ).fit(z, res[:, j])

    def term(x: np.ndarray) -> np.ndarray:
        out = np.zeros((len(x), coef.shape[0]))
        zero = np.zeros((1, x.shape[1]))
        for j, m in models.items():
            out[:, j] = m.predict(x) - m.predict(zero)[0]  # 0 on a face at rest
        return out

    return term


def study(pairs, term: str, real_only: bool = False) -> dict:
    """family -> kind ("all", "real", "made-up") -> (linear, with the term) MSE x raw."""
    names = map_features.channels(pairs)
    w = map_features.blank(names, 0, PRE, rest=True)
    w.config.update(mr._rest_keys(mr.per_input(names, mr.REST, mr.PLAIN_REST)))
    feats = dict(zip(map(id, pairs), map_features.features(w, pairs), strict=True))
    only = [j for j, n in enumerate(names) if group_of(n) in mr.OWN_GAIN]
    sums: dict = {}
    for fam, group, train, test in folds(pairs):
        if group == NEUTRAL:
            continue
        fit = [feats[id(p)] for p in train]
        coef = mr.solve([mr._moments(f) for f in fit], LAM, mr._groups(names), only)
        fit = [feats[id(p)] for p in train if real(p.group)] if real_only else fit
        add = (_hinge_term if term == "hinge" else _boost_term)(fit, coef, only)
        for p in test:
            f = feats[id(p)]
            z = f.u - f.r
            lin = z @ coef.T
            outs = (f.u + f.e, np.clip(lin, 0, 1), np.clip(lin + add(z), 0, 1))  # raw first
            for kind in ("all", "real" if real(p.group) else "made-up"):
                s = sums.setdefault(fam, {}).setdefault(kind, np.zeros(3))
                s += [float(((v - f.y) ** 2).sum()) for v in outs]
    return {fam: {k: (v[1] / v[0], v[2] / v[0]) for k, v in cell.items()}
            for fam, cell in sums.items()}  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("pairs", help="a folder of pairs in several families (make pairs)")
    p.add_argument("--term", nargs="+", default=["hinge"], choices=["hinge", "boost"])
    p.add_argument("--real", action="store_true", help="the term fitted on real takes only")
    args = p.parse_args()
    pairs = paired.load(args.pairs, require_meta=True)
    kinds = ("all", "real", "made-up")
    print("| term | family | " + " | ".join(f"{k}: linear -> with term" for k in kinds) + " |")
    print("|---|---|" + "---|" * len(kinds))
    for term in args.term:
        label = term + (" (real takes)" if args.real else "")
        for fam, cell in sorted(study(pairs, term, args.real).items()):
            said = [f"{cell[k][0]:.3f} -> {cell[k][1]:.3f}" if k in cell else "-" for k in kinds]
            print(f"| {label} | {fam} | " + " | ".join(said) + " |", flush=True)


if __name__ == "__main__":
    main()
