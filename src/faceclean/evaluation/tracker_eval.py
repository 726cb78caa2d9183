"""The tracker table of docs/RESULTS.md: cleaners of MediaPipe's output, judged on pairs
no training saw.

Folds leave one performance source out (``paired.split``): a fold trains on every other
source in the training render settings and is scored on the left-out source, once in the
training settings and once in the held-out render setting. Every pair has its own scene
seed, so test identities, performances and (for the held-out column) lighting and camera
are all unseen. Rows:

- raw: MediaPipe's scores as they come;
- one-euro: One Euro tuned on the fold's training pairs (a grid, by MSE);
- calibration + one-euro: each test pair's own calibration clip (``pairs --rom``: the
  same face and camera, a neutral hold then a range of motion) measured by
  ``calibration.calibrate(rom=True)``, its levels applied before the fold's tuned One
  Euro, as ``calibrate --rom`` then ``clean --calibration`` would (only where every test
  pair of the fold has its clip);
- ridge: a per-channel ridge map over all inputs, fitted on the fold's training pairs;
- lstm: the paper's derivative LSTM trained on the same pairs (optional: slow on a CPU);
- tracker-map: ours (learned/tracker_map.py).

The learned rows train on the fold's training pairs and their calibration clips
(``paired.with_clips``), all on the same data; the test pairs' clips are never trained on.

Columns: MSE (and as a ratio of raw), MSE per channel group, blink closure, jitter ratio
(vs the truth's), lag in ms. Each is the mean over the fold's pairs, then over folds
weighted by frames for MSE (plain means for the rest): over every fold ("overall"), and
over the folds of real performances only ("real": the synthetic performers' fold left
out; their full-range channels move independently, combinations no face makes, and their
raw error is about 5x a real take's, so they outweigh the rest of "overall").
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import GROUPS
from faceclean.datasets import paired
from faceclean.datasets.paired import Pair
from faceclean.evaluation.metrics import summary
from faceclean.filters.base import Stepper

ONE_EURO_GRID = [(mc, b) for mc in (0.5, 1.0, 2.0, 4.0) for b in (0.0, 0.3, 1.0, 3.0)]
Build = Callable[[Sequence[str]], Stepper | None]  # names -> a cleaner (None: raw)
Report = Callable[[str], None]


@dataclass(frozen=True)
class PerPair:
    """A row whose cleaner is made for each pair (from the pair's own calibration clip)."""

    make: Callable[[Pair], Stepper]


def outputs(build: Build | PerPair, pairs: Sequence[Pair]) -> list[Animation]:
    """Every pair's tracked take cleaned; causal cleaners step all pairs at once as streams."""
    from faceclean.evaluation.harness import run_streams

    if isinstance(build, PerPair):
        return [build.make(p).clean(p.tracked) for p in pairs]
    names = pairs[0].tracked.names
    cleaner = build(names)
    if cleaner is None:
        return [p.tracked for p in pairs]
    if any(p.tracked.names != names for p in pairs):
        return [build(p.tracked.names).clean(p.tracked) for p in pairs]
    ys = run_streams(cleaner, [p.tracked for p in pairs])
    return [p.tracked.with_values(y) for p, y in zip(pairs, ys, strict=True)]


def mse(build: Build, pairs: Sequence[Pair]) -> float:
    """MSE over every frame of ``pairs`` (channels matched by name), the tuning score."""
    from faceclean.evaluation.metrics import paired as matched

    sq, n = 0.0, 0
    for out, p in zip(outputs(build, pairs), pairs, strict=True):
        a, b, _ = matched(out, p.truth)
        err = (a - b) ** 2
        err = err[np.isfinite(err)]
        sq, n = sq + float(err.sum()), n + err.size
    return sq / max(n, 1)


def scores(build: Build, pairs: Sequence[Pair]) -> dict[str, float]:
    """Mean measures of one cleaner over ``pairs``; MSE also per group."""
    rows = []
    sq = {g: [] for g in GROUPS}
    for out, p in zip(outputs(build, pairs), pairs, strict=True):
        s = summary(out, p.truth)
        s["frames"] = int(out.valid.sum())
        rows.append(s)
        for g, members in GROUPS.items():
            err = _group_err(out, p.truth, members)
            if err is not None:
                sq[g].append(err)
    w = np.array([r["frames"] for r in rows], float)
    res = {"mse": float(np.average([r["mse"] for r in rows], weights=w))}
    for key in ("jitter_ratio", "lag_ms", "blink_closure"):
        res[key] = float(np.nanmean([r[key] for r in rows]))
    for g, errs in sq.items():
        if errs:
            res[f"mse_{g}"] = float(np.mean(errs))
    res["pairs"] = len(rows)
    res["frames"] = int(w.sum())
    return res


def _group_err(out: Animation, truth: Animation, members: Sequence[str]) -> float | None:
    x, px = out.arkit(members)
    y, _ = truth.arkit(members)
    if not px.any():
        return None
    err = (x[:, px] - y[:, px]) ** 2
    err = err[np.isfinite(err)]
    return float(err.mean()) if err.size else None


def tune_one_euro(train: Sequence[Pair]) -> tuple[float, float]:
    """(min_cutoff Hz, beta) of the grid with the lowest training MSE."""
    from faceclean.filters.one_euro import OneEuro

    best = None
    for mc, beta in ONE_EURO_GRID:
        score = mse(lambda n, mc=mc, beta=beta: OneEuro(names=n, min_cutoff=mc, beta=beta), train)
        if best is None or score < best[0]:
            best = (score, (mc, beta))
    assert best is not None
    return best[1]


def evaluate(
    folder: str | Path,
    held_out: str = "window",
    lstm: bool = False,
    lstm_epochs: int = 4,
    work: str | Path | None = None,
    report: Report | None = None,
) -> dict[str, Any]:
    """Every fold of the pairs in ``folder``: {"folds": {group: {row: {split: scores}}},
    "overall": {row: {split: scores}}, "pairs": counts, "chosen": {group: the fold's tracker
    map choices (pre-filter, shrinkage, detail scale, blink knee)}, "one_euro": {group: the
    fold's tuned One Euro {"min_cutoff": Hz, "beta": beta}}}."""
    from faceclean.filters.one_euro import OneEuro
    from faceclean.learned.lstm import Learned
    from faceclean.learned.tracker_map import TrackerMap
    from faceclean.neural import pair_lstm
    from faceclean.neural import tracker_map as fit

    report = report or (lambda _s: None)
    pairs = paired.load(folder, require_meta=True)
    work = Path(work) if work else Path(folder) / ".eval"
    work.mkdir(parents=True, exist_ok=True)
    folds: dict[str, Any] = {}
    chosen: dict[str, Any] = {}  # group -> the fold map's choices (what each fold picked)
    one_euro: dict[str, dict[str, float]] = {}  # group -> the fold's tuned One Euro
    for group in paired.groups(pairs):
        train, test, held = paired.split(pairs, group, held_out)
        if not train or not (test or held):
            continue
        inner_val = [p for p in train if p.group == _largest_other(train)]
        inner_train = [p for p in train if p not in inner_val]
        report(f"fold {group}: {len(train)} training pairs, {len(test)} + {len(held)} test")
        mc, beta = tune_one_euro(train)
        one_euro[group] = {"min_cutoff": float(mc), "beta": float(beta)}
        # every learned row trains on the same data: the pairs and their calibration clips
        inner_train, inner_val = paired.with_clips(inner_train), paired.with_clips(inner_val)
        ridge = fit.fit_ridge(inner_train, inner_val)
        mapped = fit.fit(inner_train, inner_val)
        pre = mapped.arrays
        chosen[group] = {
            "pre_filter": [float(pre[k][0]) for k in ("min_cutoff", "beta", "d_cutoff")]
            if mapped.config["prefilter"] else None,
            **{k: mapped.config.get(k) for k in ("lam", "detail_scale", "lift_knee", "lift_top")},
        }  # fmt: skip
        rows: dict[str, Build] = {
            "raw": lambda n: None,
            f"one-euro (tuned {mc:g} Hz, beta {beta:g})": lambda n, mc=mc, beta=beta: OneEuro(
                names=n, min_cutoff=mc, beta=beta
            ),
        }
        if all(p.rom is not None for p in test + held):
            rows["calibration + one-euro"] = PerPair(
                lambda p, mc=mc, beta=beta: calibrated_one_euro(p, mc, beta)
            )
        rows["ridge map"] = lambda n, w=ridge: TrackerMap(weights=w, names=n)
        if lstm:
            path = work / f"lstm-{group}.npz"
            # a CPU budget: chunks without overlap (a quarter of the paper's work an epoch)
            pair_lstm.train_lstm(inner_train, inner_val, path, epochs=lstm_epochs,
                                 stride=pair_lstm.T)  # fmt: skip
            rows["paper LSTM on pairs"] = lambda n, path=path: Learned(model=path, names=n)
        rows["tracker map (ours)"] = lambda n, w=mapped: TrackerMap(weights=w, names=n)
        for d in (0.0, 1.0):  # what the user's ``--set detail=`` trades, on the same map
            rows[f"tracker map, detail {d:g}"] = lambda n, w=mapped, d=d: TrackerMap(
                weights=w, names=n, detail=d
            )
        folds[group] = {
            name: {"test": scores(b, test) if test else None,
                   "held": scores(b, held) if held else None}
            for name, b in rows.items()
        }  # fmt: skip
        report(f"fold {group}: " + _line(folds[group]))
    from faceclean.synthetic.engine import SYNTH_GROUP  # numpy only

    real = {g: f for g, f in folds.items() if g != SYNTH_GROUP}
    return {"folds": folds, "overall": _overall(folds), "real": _overall(real) if real else None,
            "pairs": paired.summary_json(pairs), "chosen": chosen,
            "one_euro": one_euro}  # fmt: skip


def calibrated_one_euro(pair: Pair, min_cutoff: float, beta: float) -> Stepper:
    """One Euro behind the levels ``calibrate --rom --tracker mediapipe`` measures on the
    pair's calibration clip."""
    from faceclean.adjust import Adjusted
    from faceclean.calibration import calibrate
    from faceclean.filters.one_euro import OneEuro

    assert pair.rom is not None
    names = pair.tracked.names
    levels = calibrate(pair.rom, rom=True, tracker="mediapipe")
    return Adjusted(OneEuro(names=names, min_cutoff=min_cutoff, beta=beta), levels, names)


def _largest_other(train: Sequence[Pair]) -> str:
    """The training source with the most pairs: the inner validation set for early stops."""
    counts: dict[str, int] = {}
    for p in train:
        counts[p.group] = counts.get(p.group, 0) + 1
    return max(sorted(counts), key=counts.get)


def _line(fold: dict) -> str:
    raw = fold["raw"]["test"] or fold["raw"]["held"]
    parts = []
    for name, r in fold.items():
        s = r["test"] or r["held"]
        parts.append(f"{name.split(' (')[0]} {s['mse'] / raw['mse']:.2f}x")
    return ", ".join(parts)


def _overall(folds: dict) -> dict:
    """Rows by name (the one-euro row's tuning dropped from its name), frame-weighted MSE."""
    out: dict[str, dict] = {}
    for fold in folds.values():
        for name, splits in fold.items():
            key = name.split(" (tuned")[0]
            for split, s in splits.items():
                if s is not None:
                    out.setdefault(key, {}).setdefault(split, []).append(s)
    table: dict[str, dict] = {}
    for key, splits in out.items():
        table[key] = {}
        for split, ss in splits.items():
            w = np.array([s["frames"] for s in ss], float)
            agg = {"mse": float(np.average([s["mse"] for s in ss], weights=w))}
            for k in ss[0]:
                if k not in ("mse", "frames", "pairs"):
                    agg[k] = float(np.nanmean([s.get(k, np.nan) for s in ss]))
            agg["pairs"] = int(sum(s["pairs"] for s in ss))
            table[key][split] = agg
    return table
