"""The tracker map's blink lift (learned/tracker_map.py ``lift_gain``/``lift_knee``), fitted.

A least-squares map cannot give back a peak the tracker under-reads: a closing eye that
MediaPipe reads at a quarter. The lift can. Each blink output j becomes
``max(m_j, clip(l_j / max(1, top), 0, 1))``, ``l_j = g_j (p_j - r_j - k)``: its own input's
rise above the stream's rest past a knee k (p_j the raw input low-passed, as the runtime
reads it), times a gain g. ``gains`` fits g for a knee
(the median of truth / rise where an eye closes); ``choose`` takes the knee (None: no lift)
and whether the top follows the stream's largest lift so far (``lift_top``) that score best
leaving one source out, with a price on blink closure outside ``CLOSURE_BAND`` and one on
the blinks' own MSE over raw's: a gain that closes every blink also lifts an eye that only
narrows (a look down, a squint), and the blink channels must not end worse than the raw
tracker's (docs/MODEL.md, twenty-second round).

The folds are the fit's (neural/tracker_map.py: the linear part without each source, its
held-out features), as are its score and linear setter: passed in, since that module
calls this one.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from faceclean.learned.map_weights import MAX_LIFT, MapWeights
from faceclean.neural.map_groups import at_rest

# The blink lift's knees (rise above rest, weight units; None: no lift) and the closure
# (output peak / true peak) a blink should reach: below 0.9 an eye does not read as
# closed, above 1.1 it slams; a candidate outside the band pays its distance from it.
KNEES: tuple[float | None, ...] = (None, 0.1, 0.2, 0.3, 0.4)
# The lift's top: fixed (a gain of g), or following the stream's largest lift so far
# (``lift_top``: the gain falls for an eye that reads higher than the training faces').
TOPS = (False, True)
CLOSURE_BAND = (0.9, 1.1)
LIFT_FROM = 0.5  # the gain is fitted where the truth is over this (an eye closing)


class Fold(NamedTuple):
    """One fold (a source, or a look and a source) left out of the fit."""

    linear: tuple[np.ndarray, ...]  # (A, c, d): the linear part fitted without the fold
    train: Sequence[Any]  # the performances' features the fold's gains are fitted on
    held: Sequence[Any]  # the fold's own performances' features, which it is scored on
    raw_mse: float  # raw MSE over ``held``: what the fold's MSE is a ratio to


def gains(w: MapWeights, feats: Sequence[Any], knee: float) -> np.ndarray:
    """(M,) lift gains for ``knee`` (0 where no lift): per blink output, the median over
    ``feats``' frames whose truth is over LIFT_FROM of truth / (rise - knee), the rise
    the input of the same name's p - r (frames where it has not passed the knee skipped)."""
    from faceclean.evaluation.metrics import BLINK_CHANNELS
    from faceclean.neural.map_features import low_pass

    out = np.zeros(len(w.outputs))
    for i, name in enumerate(w.outputs):
        if name not in BLINK_CHANNELS or name not in w.inputs:
            continue
        j = w.inputs.index(name)
        p = [low_pass(f.u[:, [j]] + f.e[:, [j]], f.t, w.lift_tau)[:, 0] for f in feats]
        over = np.concatenate([q - f.r[:, j] - knee for q, f in zip(p, feats, strict=True)])
        y = np.concatenate([f.y[:, i] for f in feats])
        sel = (y > LIFT_FROM) & (over > 0.02)
        if sel.sum() >= 10:
            out[i] = float(np.clip(np.median(y[sel] / over[sel]), 0.0, MAX_LIFT))
    return out


def set_gains(w: MapWeights, g: np.ndarray, knee: float) -> None:
    """Sets ``w``'s lift arrays: the gains ``g`` (M,), the knee where a gain is > 0."""
    w.arrays["lift_gain"] = g
    w.arrays["lift_knee"] = np.where(g > 0, knee, 0.0)


def clear(w: MapWeights) -> None:
    """No lift: ``w``'s gains 0, its config's knee None and top off."""
    set_gains(w, np.zeros(len(w.outputs)), 0.0)
    w.config.update(lift_knee=None, lift_top=False)


class Choice(NamedTuple):
    """One (knee, top) scored over the folds."""

    score: float  # mean MSE x raw, x the jitter's price, x the closure's, x the blinks'
    knee: float | None
    top: bool
    closure: float  # mean output peak / true peak over every held-out blink
    blinks: float  # the blink outputs' MSE x raw, over every held-out frame


def choose(
    w: MapWeights,
    performed: Sequence[Any],
    folds: Mapping[str, Fold],
    score: Callable[..., tuple[float, ...]],
    set_linear: Callable[..., None],
    report: Callable[[dict[str, Any]], None],
    budget: float,
    knees: Sequence[float | None] = KNEES,
    tops: Sequence[bool] = TOPS,
    admissible: Callable[[MapWeights], bool] | None = None,
) -> None:
    """Sets ``w``'s blink lift: the knee and top that score best over ``folds`` (each
    fold's linear part and its gains fitted without it, scored on its held-out
    performances by MSE x raw x the jitter's price (1 + jitter over ``budget`` x the
    truth's, when over) x (1 + the mean closure's distance outside CLOSURE_BAND) x (1 + the
    blink outputs' MSE over raw's, where over)); the gains then fitted on ``performed``,
    every performance. ``score(w, feats, closure=True)`` gives (MSE, jitter, closure, the
    blinks' MSE x raw) and ``set_linear(w, a, c, d)`` sets the linear part
    (tracker_map.py's); ``w``'s linear part is left as it was. With ``admissible``, the
    best lift the map keeps admissible with its gains set (no lift when none is)."""
    linear = {k: w.arrays[k].copy() for k in ("a", "b", "c", "detail")}
    none = np.zeros(len(w.outputs))
    lo, hi = CLOSURE_BAND
    found: list[Choice] = []
    for knee, top in [(k, t) for k in knees for t in tops if k is not None or not t]:
        trial = MapWeights(dict(w.config, lift_top=top), w.arrays)  # w's arrays, this top
        ratios, jits, closures, eyes = [], [], [], []
        for key, fold in folds.items():
            if at_rest(key):
                continue
            set_linear(trial, *fold.linear)
            g = none if knee is None else gains(trial, fold.train, knee)
            set_gains(trial, g, knee or 0.0)
            mse, jit, close, blinks = score(trial, fold.held, closure=True)
            ratios.append(mse / max(fold.raw_mse, 1e-12))
            jits.append(jit)
            closures.append(close)
            eyes.append(blinks)
        ratio = float(np.mean(ratios))
        jit = float(np.nanmean(jits)) if np.isfinite(jits).any() else 0.0
        close = float(np.nanmean(closures)) if np.isfinite(closures).any() else 1.0
        blinks = float(np.nanmean(eyes)) if np.isfinite(eyes).any() else 1.0
        price = max(0.0, lo - close) + max(0.0, close - hi)
        total = ratio * (1.0 + max(0.0, jit / budget - 1.0)) * (1.0 + price)
        total *= 1.0 + max(0.0, blinks - 1.0)
        report({"event": "lift", "knee": knee, "top": top, "val_mse": ratio, "jitter": jit,
                "closure": close, "blinks": blinks, "cv": len(folds)})  # fmt: skip
        found.append(Choice(total, knee, top, close, blinks))
    w.arrays.update(linear)
    for best in sorted(found, key=lambda c: c.score):
        set_gains(
            w, none if best.knee is None else gains(w, performed, best.knee), best.knee or 0.0
        )
        w.config.update(lift_knee=best.knee, lift_top=best.top, val_closure=best.closure)
        if admissible is None or best.knee is None or admissible(w):
            return
        report({"event": "lift refused", "knee": best.knee, "top": best.top})
    clear(w)
