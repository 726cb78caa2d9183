"""The one evaluation harness: the conditions a cleaner is judged under, the corrupted
streams drawn for them, and many streams run as one padded batch.

Both the RESULTS protocol (evaluation/evaluate.py) and the trainers' validation
(neural/train.py, neural/adaptive.py, neural/validate.py) draw their streams here, so a
(condition, take, seed) gives the same corrupted stream to both.

Seeding: take i of a list is corrupted with ``default_rng([seed, i])`` (simulate) or the
seed ``seed * 1000 + i`` (degrade), whatever the condition: the artefact draw is the same
at 30, 60 and 120 fps and only the rate changes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from faceclean.animation import Animation
from faceclean.datasets import dataset, simulate
from faceclean.errors import FacecleanError
from faceclean.evaluation import degrade
from faceclean.filters import Stepper

# condition -> (simulator preset, fps or None for the preset's own draw); degrade has
# its own parameters for the same names (degrade.CONDITIONS).
CONDITIONS: dict[str, tuple[str, float | None]] = {
    "30 fps": ("iphone", 30.0),
    "60 fps": ("iphone", 60.0),
    "120 fps": ("iphone", 120.0),
    "webcam": ("webcam", None),
}
ARTEFACTS = ("degrade", "simulate")  # the independent model first: it decides
SEED = 2020  # the RESULTS streams
VALIDATION = ("60 fps", "webcam")  # the conditions the trainers validate on every epoch
VALIDATION_SEED = 7  # the trainers' streams: never the RESULTS draw of the same takes


class Stream(NamedTuple):
    """One corrupted take: its condition, "source/name", and (noisy, truth)."""

    condition: str
    name: str
    noisy: Animation
    truth: Animation


def corrupted(
    takes: Sequence[dataset.Take],
    condition: str,
    seed: int,
    seconds: float | None = None,
    artefacts: str = "simulate",
) -> list[tuple[Animation, Animation]]:
    """(noisy, truth) of every take (its first ``seconds``, or all of it) under
    ``condition`` by the artefact model ``artefacts``; channels as the take has them."""
    if artefacts not in ARTEFACTS:
        raise FacecleanError(f"unknown artefact model {artefacts!r} (known: {ARTEFACTS})")
    if condition not in CONDITIONS:
        raise FacecleanError(f"unknown condition {condition!r}: use one of {', '.join(CONDITIONS)}")
    preset, fps = CONDITIONS[condition]
    pairs = []
    for i, take in enumerate(takes):
        clean = take.animation if seconds is None else head(take.animation, seconds)
        if artefacts == "degrade":
            pairs.append(degrade.degrade(clean, seed=seed * 1000 + i, condition=condition))
            continue
        rng = np.random.default_rng([seed, i])
        params = simulate.sample_params(rng, preset)
        if fps is not None:
            params = dataclasses.replace(params, fps=fps)
        pairs.append(simulate.apply(clean, params, rng))
    return pairs


def streams(
    takes: Sequence[dataset.Take],
    conditions: Sequence[str] = VALIDATION,
    seed: int = VALIDATION_SEED,
) -> list[Stream]:
    """Every take under every condition (simulate), in that order: the trainers' streams."""
    return [
        Stream(cond, f"{take.source}/{take.name}", noisy, truth)
        for cond in conditions
        for take, (noisy, truth) in zip(takes, corrupted(takes, cond, seed), strict=True)
    ]


def head(anim: Animation, seconds: float) -> Animation:
    """The first ``seconds`` of a take (from its first frame)."""
    keep = anim.times <= anim.times[0] + seconds
    return Animation(anim.times[keep], anim.values[keep], anim.names, dict(anim.meta))


def pad(times: Sequence[np.ndarray], values: Sequence[np.ndarray]) -> tuple[np.ndarray, ...]:
    """S streams of (N_i,) s and (N_i, M) as one batch: t (S, N) and x (S, N, M), N the
    longest; past a stream's end both are NaN (missing frames: held, ignored)."""
    n, m = max(len(v) for v in values), values[0].shape[1]
    t = np.full((len(values), n), np.nan)
    x = np.full((len(values), n, m), np.nan)
    for j, (tj, vj) in enumerate(zip(times, values, strict=True)):
        t[j, : len(vj)], x[j, : len(vj)] = tj, vj
    return t, x


def unpad(y: np.ndarray, values: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Outputs y (S, N, M') cut back to each stream's N_i rows; a missing input frame (an
    all-NaN row of ``values``) stays missing in the output, as ``clean()`` leaves it."""
    out = []
    for j, vj in enumerate(values):
        yj = y[j, : len(vj)].copy()
        yj[np.isnan(vj).all(axis=1)] = np.nan
        out.append(yj)
    return out


def run_streams(cleaner: Stepper, inputs: Sequence[Animation]) -> list[np.ndarray]:
    """Clean every take; causal cleaners step all takes at once as streams (S, M)."""
    if cleaner.offline:
        return [cleaner.clean(a).values for a in inputs]
    values = [a.values for a in inputs]
    t, x = pad([a.times for a in inputs], values)
    t, x = t.T.copy(), x.swapaxes(0, 1).copy()  # time-major: (N, S), (N, S, M)
    cleaner.reset()
    y = np.stack([cleaner.step(x[i], t[i]) for i in range(len(t))], axis=1)  # (S, N, M)
    return unpad(y, values)
