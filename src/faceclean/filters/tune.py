"""Tuning: search a classical cleaner's parameters against ground truth.

Objective: the MSE between the cleaned noisy input and the truth over every frame of
every (noisy, truth) pair (SPEC section 5's first measure), per unit: the whole face
(global) or each channel group of faceclean.channels.GROUPS (``per_group``; channels
outside the five groups form a sixth unit, "other").

Search, in log space within ``SPACES`` (physical units): a coarse grid (16 points for one
parameter, 8 x 8 for two), then REFINE passes of a 5-point-per-parameter grid around each
unit's best, halving the spacing each time (final resolution about 1/16 of the coarse
step, ~10 % in value). Every pass is one vectorised run: candidates are laid side by side
as extra channels (C candidates x M channels, per-channel parameter arrays), and the
pairs, cut into segments of ``segment`` seconds, are stepped together as streams, so
all groups and candidates are tuned at once. Offline cleaners are run per candidate.

Kalman's steady state depends on q / r^2 only, so r is fixed and q is searched;
One Euro's (and the rotation filter's) d_cutoff stays at Casiez et al.'s 1 Hz;
Savitzky-Golay keeps polyorder 2.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import group_of
from faceclean.errors import FacecleanError
from faceclean.evaluation.metrics import interp_rows, paired
from faceclean.filters import Stepper, cleaner_class, make
from faceclean.filters import presets as _presets

# method -> parameter -> (low, high), searched log-uniformly.
SPACES: dict[str, dict[str, tuple[float, float]]] = {
    "ema": {"tau": (0.002, 0.5)},  # s
    "one-euro": {"min_cutoff": (0.05, 60.0), "beta": (0.001, 100.0)},  # Hz, Hz/(unit/s)
    "kalman": {"q": (0.01, 1e7)},  # unit^2/s^3
    "gaussian": {"sigma": (0.002, 0.2)},  # s
    "savgol": {"window": (0.02, 0.8)},  # s
    "rotation": {"min_cutoff": (0.05, 60.0), "beta": (0.001, 100.0)},  # Hz, Hz/(rad/s)
}
FIXED: dict[str, dict[str, float]] = {
    "one-euro": {"d_cutoff": 1.0},  # Hz
    "rotation": {"d_cutoff": 1.0},  # Hz
    "kalman": {"r": 0.02},  # unit
    "savgol": {"polyorder": 2},
}
REFINE = 3  # refinement passes
Progress = Callable[[int, int], None]  # (pass done, passes in all)


@dataclass
class Tuned:
    """A tuning result: parameters per unit, and the MSE before and after, per unit."""

    method: str
    params: dict[str, float]  # for every channel (the largest unit's values when per group)
    groups: dict[str, dict[str, float]] = field(default_factory=dict)
    mse: dict[str, float] = field(default_factory=dict)  # unit -> tuned MSE
    raw_mse: dict[str, float] = field(default_factory=dict)  # unit -> MSE of the noisy input

    def document(self, about: dict[str, Any] | None = None) -> dict[str, Any]:
        """The preset JSON document (faceclean-preset/1)."""
        doc: dict[str, Any] = {
            "format": _presets.FORMAT,
            "method": self.method,
            "params": dict(self.params),
        }
        if self.groups:
            doc["groups"] = {g: dict(v) for g, v in self.groups.items()}
        doc["about"] = {"objective": "mse", "mse": self.mse, "raw_mse": self.raw_mse}
        doc["about"].update(about or {})
        return doc

    def save(self, path: str | os.PathLike, about: dict[str, Any] | None = None) -> None:
        """Write the preset atomically; ``faceclean clean --preset PATH`` loads it."""
        doc = self.document(about)
        _presets.save(path, self.method, doc["params"], doc.get("groups"), doc["about"])

    def build(self, names: Sequence[str]) -> Stepper:
        return _presets.build(self.document(), names)


def align(noisy: Animation, clean: Animation) -> Animation:
    """The clean take at the noisy take's instants (linear in time; NaN outside it)."""
    if noisy.n_frames == clean.n_frames and np.allclose(noisy.times, clean.times, atol=1e-6):
        return clean
    ok = clean.valid & np.isfinite(clean.times)
    if not ok.any():  # every truth frame is tracking loss: nothing to align, nothing to score
        raise FacecleanError(
            "nothing to tune on: every frame of the truth is tracking loss (no values)"
        )
    t, v = clean.times[ok], clean.values[ok]
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    keep = np.concatenate([[True], np.diff(t) > 0])
    t, v = t[keep], v[keep]
    if len(t) < 2 or noisy.times.max() < t[0] or noisy.times.min() > t[-1]:
        raise FacecleanError("the truth does not overlap the noisy take in time")
    at = noisy.times
    out = interp_rows(t, v, np.clip(at, t[0], t[-1]))
    out[(at < t[0] - 1e-6) | (at > t[-1] + 1e-6) | ~np.isfinite(at)] = np.nan
    return Animation(at, out, clean.names, dict(clean.meta))


def _segments(pairs, names, seconds: float):
    """Pairs cut into pieces of <= ``seconds``, padded: t (T, S), x and y (T, S, M)."""
    pieces = []
    for noisy, truth in pairs:
        p, y, keys = paired(noisy, truth)
        if set(names) - set(keys):
            raise FacecleanError("every (noisy, truth) pair must carry the same channels")
        if not np.isfinite(noisy.times).all():
            raise FacecleanError("the noisy take has non-finite timestamps")
        order = [keys.index(n) for n in names]
        p, y, t = p[:, order], y[:, order], noisy.times
        edges = np.searchsorted(t, np.arange(t[0], t[-1] + seconds, seconds)[1:])
        for a, b in itertools.pairwise([0, *edges.tolist(), len(t)]):
            if b - a >= 2:
                pieces.append((t[a:b], p[a:b], y[a:b]))
    if not pieces:
        raise FacecleanError("nothing to tune on: give (noisy, truth) pairs with frames")
    n, s, m = max(len(q[0]) for q in pieces), len(pieces), len(names)
    t = np.full((n, s), np.nan)
    x = np.full((n, s, m), np.nan)
    y = np.full((n, s, m), np.nan)
    for j, (tj, xj, yj) in enumerate(pieces):
        t[: len(tj), j], x[: len(tj), j], y[: len(tj), j] = tj, xj, yj
    return t, x, y


def _masked_sse(out: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared error (C, M) of out (S, C, M) vs y (S, M) where x's frame and y exist."""
    ok = ~np.isnan(x).all(axis=-1, keepdims=True) & np.isfinite(y)  # (S, M)
    err = np.where(ok[:, None, :], out - y[:, None, :], 0.0)
    return (err**2).sum(axis=0), ok.sum(axis=0)


def _evaluate(method, cand, names, t, x, y) -> tuple[np.ndarray, np.ndarray]:
    """Sum of squared errors (C, M) and frame counts (M,) of candidates cand[k] (C, M)."""
    c, m = next(iter(cand.values())).shape
    fixed = FIXED.get(method, {})
    if not cleaner_class(method).offline:
        params = {k: v.reshape(-1) for k, v in cand.items()} | fixed
        cleaner = make(method, params, names=tuple(names) * c)
        sse, cnt = np.zeros((c, m)), np.zeros(m)
        for i in range(t.shape[0]):
            out = cleaner.step(np.tile(x[i], (1, c)), t[i]).reshape(-1, c, m)
            e, k = _masked_sse(out, x[i], y[i])
            sse += e
            cnt += k
        return sse, cnt
    sse, cnt = np.zeros((c, m)), np.zeros(m)
    stack = np.stack([cand[k] for k in cand], axis=-1)  # (C, M, D)
    for ci in range(c):
        for combo in np.unique(stack[ci], axis=0):
            cols = (stack[ci] == combo).all(axis=1)
            cleaner = make(
                method, dict(zip(cand, combo.tolist(), strict=True)) | fixed, names=names
            )
            for j in range(t.shape[1]):
                ok = np.isfinite(t[:, j])
                out = cleaner.clean(Animation(t[ok, j], x[ok, j], names)).values
                e, k = _masked_sse(out[:, None, :], x[ok, j], y[ok, j])
                sse[ci, cols] += e[0, cols]
                if ci == 0:
                    cnt[cols] += k[cols]
    return sse, cnt


def tune(
    method: str,
    pairs: Sequence[tuple[Animation, Animation]],
    *,
    per_group: bool = False,
    segment: float = 20.0,
    progress: Progress | None = None,
) -> Tuned:
    """Search ``method``'s parameters minimising MSE on (noisy, truth) pairs.

    Pairs are at the same instants (``simulate.corrupt`` gives them so; ``align`` makes
    them so). Channels are matched by canonical name; the first pair's channels count.
    """
    if method not in SPACES:
        raise FacecleanError(f"cannot tune {method!r} (tunable: {', '.join(SPACES)})")
    if not pairs:
        raise FacecleanError("nothing to tune on: no (noisy, truth) pairs")
    names = paired(*pairs[0])[2]
    t, x, y = _segments(pairs, names, segment)
    space = SPACES[method]
    keys = list(space)
    lo = np.log([space[k][0] for k in keys])  # (D,)
    hi = np.log([space[k][1] for k in keys])
    units = [(group_of(n) or "other") if per_group else "all" for n in names]
    unit_names = list(dict.fromkeys(units))
    unit_of = np.array([unit_names.index(u) for u in units])  # (M,)
    scored = (~np.isnan(x).all(axis=-1, keepdims=True) & np.isfinite(y)).sum(axis=(0, 1))  # (M,)
    for u, g in enumerate(unit_names):  # an MSE over no cells would claim 0.0
        if not scored[unit_of == u].any():
            where = "" if g == "all" else f" for the {g} channels"
            raise FacecleanError(
                f"nothing to tune on{where}: the truth has no finite value where the noisy "
                "take has a frame (all tracking loss?)"
            )

    d = len(keys)
    n1 = 16 if d == 1 else 8
    step = (hi - lo) / (n1 - 1)
    grid = np.array(list(itertools.product(*[np.linspace(0, 1, n1)] * d)))  # (C, D)
    cand_log = np.broadcast_to(lo + grid * (hi - lo), (len(unit_names), len(grid), d))
    best_log = np.zeros((len(unit_names), d))
    best_cost = np.full(len(unit_names), np.inf)
    raw = _raw_mse(x, y, unit_of, len(unit_names))
    passes = 1 + REFINE
    for p in range(passes):
        if p > 0:
            offs = np.array(list(itertools.product(*[np.linspace(-1, 1, 5)] * d)))
            step = step / 2 if p > 1 else step
            cand_log = np.clip(best_log[:, None, :] + offs[None] * step, lo, hi)  # (U, C, D)
        per_ch = cand_log[unit_of]  # (M, C, D)
        cand = {k: np.exp(per_ch[:, :, i]).T for i, k in enumerate(keys)}  # each (C, M)
        sse, cnt = _evaluate(method, cand, names, t, x, y)
        for u in range(len(unit_names)):
            cols = unit_of == u
            cost = sse[:, cols].sum(axis=1) / max(cnt[cols].sum(), 1)  # (C,)
            i = int(np.argmin(cost))
            if cost[i] < best_cost[u]:
                best_cost[u], best_log[u] = cost[i], cand_log[u, i]
        if progress is not None:
            progress(p + 1, passes)

    def values(u: int) -> dict[str, float]:
        return {k: float(f"{np.exp(best_log[u, i]):.4g}") for i, k in enumerate(keys)}

    fixed = dict(FIXED.get(method, {}))
    largest = int(np.argmax(np.bincount(unit_of)))
    groups = {g: values(u) for u, g in enumerate(unit_names) if per_group and g != "other"}
    return Tuned(
        method=method,
        params=values(largest) | fixed,
        groups=groups,
        mse={g: float(best_cost[u]) for u, g in enumerate(unit_names)},
        raw_mse={g: float(raw[u]) for u, g in enumerate(unit_names)},
    )


def _raw_mse(x: np.ndarray, y: np.ndarray, unit_of: np.ndarray, n_units: int) -> np.ndarray:
    """MSE of the noisy input itself, per unit (U,)."""
    err = (x - y) ** 2  # (T, S, M)
    ok = np.isfinite(err)
    sse = np.where(ok, err, 0.0).sum(axis=(0, 1))
    cnt = ok.sum(axis=(0, 1))
    return np.array(
        [sse[unit_of == u].sum() / max(cnt[unit_of == u].sum(), 1) for u in range(n_units)]
    )
