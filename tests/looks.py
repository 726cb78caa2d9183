"""Pairs of made-up looks for the tracker map's held-out-look tests (issue 34): each look's
tracker re-mixes gaze its own way (as one renderer's eyes do), sits at its own resting
reading, and reads some channels as zero that the truth moves (MediaPipe's jawForward,
noseSneer); the truth is the independent performer's, plus a face at rest per look."""

from __future__ import annotations

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.datasets import paired
from faceclean.datasets.performer import independent
from faceclean.learned.tracker_map import TrackerMap

NAMES = tuple(n for n in ARKIT52 if n != "tongueOut")
GAZE = [i for i, n in enumerate(NAMES) if n.startswith("eyeLook")]
ZERO_READ = [NAMES.index(n) for n in ("jawForward", "noseSneerLeft", "noseSneerRight",
                                        "cheekSquintLeft", "cheekSquintRight")]  # fmt: skip
FPS = 30.0
PRE = [(2.0, 50.0, 4.0)]  # one pre-filter: the test is about the map, not the filter


def tracker(look: int, noise: float = 0.01):
    """A look's tracker: (N, 51) truth -> (N, 51) readings, its own gaze mix and rest, and
    ``noise`` (weight units, one sd) on every reading."""
    rng = np.random.default_rng(look)
    mix = np.eye(len(GAZE)) * rng.uniform(0.4, 0.8) + rng.uniform(0, 0.35, (len(GAZE),) * 2)
    rest = rng.uniform(0.0, 0.12, len(NAMES))

    def read(y: np.ndarray, seed: int) -> np.ndarray:
        x = 0.8 * y + rest
        x[:, GAZE] = y[:, GAZE] @ mix.T + rest[GAZE]
        x[:, ZERO_READ] = 0.0
        jitter = np.random.default_rng([look, seed]).normal(0, noise, x.shape)
        return np.clip(x + jitter, 0.0, 1.0)

    return read


def pairs(look: int, sources: int = 4, per: int = 2, noise: float = 0.01) -> list[paired.Pair]:
    read = tracker(look, noise)
    out = []
    for s in range(sources):
        for k in range(per):
            seed = 1000 * look + 10 * s + k
            truth = independent(12.0, seed, fps=FPS)
            y = truth.arkit(NAMES)[0]
            out.append(paired.Pair(f"{look}-{s}-{k}", Animation(truth.times, read(y, seed), NAMES),
                                   Animation(truth.times, y, NAMES), f"src{s}", "studio",
                                   family=f"look{look}"))  # fmt: skip
    t = np.arange(int(3 * FPS)) / FPS  # a face at rest: every weight 0
    zero = np.zeros((len(t), len(NAMES)))
    out.append(paired.Pair(f"{look}-rest", Animation(t, read(zero, 99), NAMES),
                           Animation(t, zero, NAMES), "neutral", "studio",
                           family=f"look{look}"))  # fmt: skip
    return out


def cleaned(w, test):
    return [(TrackerMap(weights=w, names=NAMES).clean(p.tracked).values, p) for p in test]


def gaze_ratio(w, test) -> float:
    num = den = 0.0
    for out, p in cleaned(w, test):
        if p.group == "neutral":
            continue
        y = p.truth.values[:, GAZE]
        num += float(((out[:, GAZE] - y) ** 2).sum())
        den += float(((p.tracked.values[:, GAZE] - y) ** 2).sum())
    return num / den


def zero_read_level(w, test) -> float:
    """The zero-read channels' mean output where the tracker reads them as 0."""
    outs = [out[:, ZERO_READ] for out, _ in cleaned(w, test)]
    return float(np.mean(np.concatenate(outs)))


def neutral_off(w, test) -> float:
    """The worst channel's mean |output - 0| on the face at rest, after half a second."""
    out, p = next((o, p) for o, p in cleaned(w, test) if p.group == "neutral")
    keep = p.tracked.times >= 0.5
    return float(np.abs(out[keep]).mean(axis=0).max())


def habits(hidden: dict[str, str], real: str = "src0") -> list[paired.Pair]:
    """The performances of looks 1 and 2, the tracker reading each of ``hidden`` (a channel
    it cannot see -> one it can) as 0: made-up performers (every source but ``real``, named
    as the made-up kinds) move it with the one it can see, the ``real`` source never."""
    from dataclasses import replace

    out = []
    for p in (p for look in (1, 2) for p in pairs(look) if p.group != "neutral"):
        made_up = p.group != real
        y, x = p.truth.values.copy(), p.tracked.values.copy()
        for h, seen in hidden.items():
            y[:, NAMES.index(h)] = y[:, NAMES.index(seen)] if made_up else 0.0
            x[:, NAMES.index(h)] = 0.0
        group = ("independent", "synthetic")[int(p.name[-1])] if made_up else p.group
        out.append(replace(p, tracked=Animation(p.tracked.times, x, NAMES),
                           truth=Animation(p.truth.times, y, NAMES), group=group))  # fmt: skip
    return out
