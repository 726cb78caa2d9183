"""Training data: clean takes -> split by take or source -> augmented, corrupted chunks.

Numpy only. One epoch, for every take: augment the clean target (per-channel gains and
offsets, a smooth time-warp, left/right mirroring), let the simulator resample it at a
tracker's rate (24-120 Hz with jittered timestamps) and degrade it with a fresh seed,
then cut (noisy, truth) into chunks of 200 frames overlapping by 150 (the paper's).
Validation uses a fixed seed and no augmentation, so its numbers are comparable.

    takes = load_takes()
    train, val = split(takes, val_sources=["jmtechart"])
    for epoch, batch in enumerate(epochs(train, seed=0, count=10)):
        batch.noisy  # (B, 200, 52) float32 ...
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52, INDEX
from faceclean.datasets import simulate
from faceclean.errors import FacecleanError
from faceclean.settings import takes_dir
from faceclean.timing import hold_last

SUFFIXES = (".csv", ".json", ".npz", ".glb", ".gltf")
LENGTH, OVERLAP = 200, 150  # frames per chunk, frames shared by consecutive chunks


@dataclass(frozen=True)
class Take:
    """One clean recording: ``source`` is the performer/app folder it came from."""

    source: str
    name: str
    animation: Animation


@dataclass
class Chunks:
    """A set of chunks, B of them, T frames each, M = 52 ARKit channels.

    noisy:    (B, T, M) float32 tracker output; frames it lost hold its last value.
    truth:    (B, T, M) float32 clean values at the same instants (held where unknown).
    times:    (B, T) float64 s from the chunk's first frame; dt = diff(times) > 0.
    valid:    (B, T) bool: truth is real and the tracker saw the frame. Losses and
              metrics use only these frames; padding and missing source rows are False.
    observed: (B, T) bool: the tracker delivered values (False in tracking-loss gaps).
    """

    noisy: np.ndarray
    truth: np.ndarray
    times: np.ndarray
    valid: np.ndarray
    observed: np.ndarray

    def __len__(self) -> int:
        return len(self.noisy)

    def subset(self, index: np.ndarray) -> Chunks:
        """The chunks at ``index`` (B',): an int or bool array."""
        return Chunks(*(a[index] for a in vars(self).values()))


def load_takes(folder: str | os.PathLike | None = None) -> list[Take]:
    """Every animation file under ``folder`` (default ``settings.takes_dir()``), sorted.

    A file's source is the name of its first-level subfolder (the folder's own name for
    files directly inside). Tracking-loss rows stay as all-NaN rows.
    """
    from faceclean.io import load

    root = Path(folder) if folder is not None else takes_dir()
    if root is None or not root.is_dir():
        raise FacecleanError(f"no takes folder: {root or 'set FACECLEAN_DATA'}")
    files = sorted(p for p in root.rglob("*") if p.suffix.lower() in SUFFIXES and p.is_file())
    takes = []
    for p in files:
        rel = p.relative_to(root)
        source = rel.parts[0] if len(rel.parts) > 1 else root.name
        takes.append(Take(source, p.stem, load(p)))
    if not takes:
        raise FacecleanError(f"no animation files under {root}")
    return takes


def holdout(
    takes: Sequence[Take], val_sources: Sequence[str] = (), seed: int = 0
) -> tuple[list[Take], list[Take]]:
    """A training run's (train, val): whole ``val_sources`` held out, or, with none
    given, 20 % of every source's takes (the trainers' rule). No take left to validate
    on (every source has one take) is refused: early stopping would keep the starting
    model and say nothing of it."""
    if val_sources:
        return split(takes, val_sources=val_sources)
    train, val = split(takes, val_fraction=0.2, seed=seed)
    if not val:
        raise FacecleanError(
            f"no take left to validate on ({len(train)} take(s), none from a source with two "
            "or more): add takes, or hold a source out with --val-sources"
        )
    return train, val


def split(
    takes: Sequence[Take],
    val_sources: Sequence[str] = (),
    val_fraction: float = 0.0,
    seed: int = 0,
) -> tuple[list[Take], list[Take]]:
    """(train, val) by whole takes, never by chunk.

    Every take of a source in ``val_sources`` goes to validation; of the other sources,
    about ``val_fraction`` of each source's takes (at least one when the fraction is > 0
    and the source has two or more), chosen by ``seed``.
    """
    unknown = set(val_sources) - {t.source for t in takes}
    if unknown:
        raise FacecleanError(f"no takes from source(s): {', '.join(sorted(unknown))}")
    rng = np.random.default_rng(seed)
    held: set[int] = {i for i, t in enumerate(takes) if t.source in val_sources}
    for source in sorted({t.source for t in takes} - set(val_sources)):
        idx = [i for i, t in enumerate(takes) if t.source == source]
        k = int(round(val_fraction * len(idx)))
        if val_fraction > 0 and len(idx) >= 2:
            k = min(max(k, 1), len(idx) - 1)
        held.update(int(i) for i in rng.permutation(idx)[:k])
    train = [t for i, t in enumerate(takes) if i not in held]
    val = [t for i, t in enumerate(takes) if i in held]
    if not train:
        raise FacecleanError("the split leaves no training takes")
    return train, val


def folds(takes: Sequence[Take]) -> list[tuple[str, list[Take], list[Take]]]:
    """Leave-one-source-out folds: (held-out source, train takes, val takes) per source."""
    sources = sorted({t.source for t in takes})
    if len(sources) < 2:
        raise FacecleanError("leave-one-source-out needs takes from two sources or more")
    return [(s, *split(takes, val_sources=[s])) for s in sources]


# Mirror image: every ...Left channel swaps with its ...Right twin. This is also right for
# gaze: looking left (eyeLookOutLeft + eyeLookInRight) becomes looking right
# (eyeLookOutRight + eyeLookInLeft), and jawLeft/mouthLeft become jawRight/mouthRight.
MIRROR = np.array(
    [
        INDEX[n[:-4] + "Right"] if n.endswith("Left") else
        INDEX[n[:-5] + "Left"] if n.endswith("Right") else i
        for i, n in enumerate(ARKIT52)
    ]
)  # fmt: skip


@dataclass(frozen=True)
class Augmentation:
    """Random changes of a clean target that keep it a plausible face."""

    gain: float = 0.2  # per-channel gain in 1 +- gain (pairs share it up to +-gain/4)
    offset: float = 0.03  # per-channel offset in +- offset (weight units)
    speed: float = 0.2  # playback speed in [1/(1+speed), 1+speed], log-uniform
    warp: float = 0.15  # +- share of a slow (2-8 s) speed wobble; < 1 keeps time increasing
    mirror: float = 0.5  # probability of the left/right mirror image
    curve: float = 0.0  # log-std of a per-channel exponent x^c (another calibration)


DEFAULT_AUGMENTATION = Augmentation()
# The adaptive cleaner's: targets of other calibrations too (issue 11).
WIDE_AUGMENTATION = Augmentation(gain=0.25, offset=0.04, curve=0.2)


def augment(anim: Animation, rng: np.random.Generator, aug: Augmentation) -> Animation:
    """An ARKit-52 copy of ``anim`` with random gains, offsets, time-warp and mirroring.

    Values stay in [0, max(1, source max)]; missing rows stay missing.
    """
    x, _ = anim.arkit()  # (N, 52)
    top = max(1.0, float(np.nanmax(x))) if np.isfinite(x).any() else 1.0
    pair = np.minimum(np.arange(52), MIRROR)  # one id per left/right pair
    gain = 1.0 + aug.gain * rng.uniform(-1.0, 1.0, 52)[pair]
    gain *= 1.0 + 0.25 * aug.gain * rng.uniform(-1.0, 1.0, 52)
    offset = aug.offset * rng.uniform(-1.0, 1.0, 52)
    x = np.clip(x * gain + offset, 0.0, top)
    if aug.curve > 0:  # drawn last among the values: older augmentations keep their draws
        x = x ** np.exp(aug.curve * rng.standard_normal(52))
    if rng.random() < aug.mirror:
        x = x[:, MIRROR]
    t = anim.times - anim.times[0]
    speed = np.exp(rng.uniform(-1.0, 1.0) * np.log1p(aug.speed))
    period = rng.uniform(2.0, 8.0)  # s
    phase = rng.uniform(0.0, 2.0 * np.pi)
    # Time-warp: t' = integral of rate, rate = (1 + warp sin(2 pi t / P + phase)) / speed.
    warped = (t - aug.warp * period / (2 * np.pi) * (np.cos(2 * np.pi * t / period + phase)
              - np.cos(phase))) / speed  # fmt: skip
    return Animation.from_arkit(warped, x)


def take_chunks(
    noisy: Animation, truth: Animation, length: int = LENGTH, overlap: int = OVERLAP
) -> Chunks:
    """Cut one (noisy, truth) pair of ARKit-52 animations into chunks (see :class:`Chunks`).

    Windows start every ``length - overlap`` frames, and one more ends at the last frame;
    a take shorter than ``length`` gives one chunk padded with invalid frames.
    """
    hop = length - overlap
    if hop <= 0:
        raise FacecleanError(f"overlap {overlap} must be smaller than the length {length}")
    x, _ = noisy.arkit()
    y, _ = truth.arkit()
    t = noisy.times
    observed = ~np.isnan(x).all(1)
    valid = observed & ~np.isnan(y).all(1)
    x, y = _filled(x, observed), _filled(y, ~np.isnan(y).all(1))
    n = len(t)
    if n < length:  # pad: frames continue at the last interval, invalid
        pad = length - n
        step = t[-1] - t[-2] if n > 1 else 1.0 / 60.0
        t = np.concatenate([t, t[-1] + step * np.arange(1, pad + 1)])
        x, y = (np.concatenate([a, np.repeat(a[-1:], pad, 0)]) for a in (x, y))
        observed, valid = (np.concatenate([m, np.zeros(pad, bool)]) for m in (observed, valid))
        n = length
    starts = list(range(0, n - length + 1, hop))
    if starts[-1] != n - length:
        starts.append(n - length)
    win = np.asarray(starts)[:, None] + np.arange(length)  # (B, T) frame indices
    times = t[win] - t[win[:, :1]]
    return Chunks(
        x[win].astype(np.float32), y[win].astype(np.float32), times, valid[win], observed[win]
    )


def _filled(values: np.ndarray, have: np.ndarray) -> np.ndarray:
    """Rows without values hold the last row that has them (leading rows take the first)."""
    if not have.any():
        return np.zeros_like(values)
    out = hold_last(values, ~have)
    out[: int(np.argmax(have))] = values[int(np.argmax(have))]
    return out


def concat(parts: Sequence[Chunks]) -> Chunks:
    """One :class:`Chunks` from many (in order)."""
    if not parts:
        empty = np.zeros((0, LENGTH))
        return Chunks(
            np.zeros((0, LENGTH, 52), np.float32), np.zeros((0, LENGTH, 52), np.float32),
            empty, empty.astype(bool), empty.astype(bool),
        )  # fmt: skip
    fields = zip(*(vars(p).values() for p in parts), strict=True)
    return Chunks(*(np.concatenate(a) for a in fields))


def make_chunks(
    takes: Sequence[Take],
    seed: int,
    *,
    preset: str = "mixed",
    strength: float = 1.0,
    augmentation: Augmentation | None = DEFAULT_AUGMENTATION,
    length: int = LENGTH,
    overlap: int = OVERLAP,
) -> Chunks:
    """Chunks of every take, corrupted with seeds drawn from ``seed`` (same seed, same
    arrays). ``augmentation=None`` leaves the clean targets as they are (validation)."""
    parts = []
    for take, child in zip(takes, np.random.SeedSequence(seed).spawn(len(takes)), strict=True):
        rng = np.random.default_rng(child)
        clean = take.animation
        if augmentation is not None:
            clean = augment(clean, rng, augmentation)
        noisy, truth = simulate.apply(clean, simulate.sample_params(rng, preset, strength), rng)
        parts.append(take_chunks(noisy, truth, length, overlap))
    return concat(parts)


def epoch_chunks(
    takes: Sequence[Take],
    seed: int,
    epoch: int,
    *,
    synthetic_minutes: float = 0.0,
    full_range: bool = False,
    **kwargs,
) -> Chunks:
    """Training chunks of one epoch: a fresh corruption and augmentation for every epoch,
    plus ``synthetic_minutes`` of new synthetic performer takes. Keywords go to
    :func:`make_chunks`. Same (seed, epoch), same arrays."""
    pool = list(takes)
    if synthetic_minutes > 0:
        pool += synthetic_takes(
            synthetic_minutes, seed=seed * 100003 + epoch, full_range=full_range
        )
    return make_chunks(pool, seed=seed * 1000003 + epoch + 1, **kwargs)


def epochs(
    takes: Sequence[Take], seed: int, count: int | None = None, **kwargs
) -> Iterator[Chunks]:
    """:func:`epoch_chunks` for epoch 0, 1, ... (``count`` of them, or forever)."""
    epoch = 0
    while count is None or epoch < count:
        yield epoch_chunks(takes, seed, epoch, **kwargs)
        epoch += 1


def validation_chunks(takes: Sequence[Take], preset: str = "mixed", seed: int = 0) -> Chunks:
    """Fixed validation chunks: no augmentation, the simulator with a fixed seed."""
    return make_chunks(takes, seed, preset=preset, augmentation=None)


def synthetic_takes(
    minutes: float, seed: int, take_seconds: float = 60.0, full_range: bool = False
) -> list[Take]:
    """``minutes`` of synthetic performer takes (source ``"synthetic"``), 60 fps;
    ``full_range``: every channel through its whole range (performer's range of motion)."""
    from faceclean.datasets import performer

    takes, left, i = [], minutes * 60.0, 0
    while left > 1.0:
        seconds = min(take_seconds, left)
        anim = performer.perform(seconds, seed=seed * 1000 + i, full_range=full_range)
        takes.append(Take("synthetic", f"synth_{seed}_{i}", anim))
        left -= seconds
        i += 1
    return takes


def batches(chunks: Chunks, batch_size: int, rng: np.random.Generator) -> Iterator[Chunks]:
    """Shuffled mini-batches of ``chunks`` (the last one may be smaller)."""
    order = rng.permutation(len(chunks))
    for i in range(0, len(order), batch_size):
        yield chunks.subset(order[i : i + batch_size])
