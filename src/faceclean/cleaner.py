"""``faceclean.Cleaner``: the runtime facade other tools code against.

    from faceclean import Cleaner
    c = Cleaner.load()                     # the shipped default cleaner
    y = c.step(x, t)                       # x (M,) in ``c.names`` order, t in seconds
    c = Cleaner.load("model.onnx", streams=64)
    Y = c.step(X, T)                       # X (64, M), T (64,): 64 faces in one call
    cleaned = c.clean(animation)           # a whole clip (resets the streams)
    c = Cleaner.load("one-euro", settings=["jawOpen.min_cutoff=2", "eyeBlink*.gain=1.2"])

``load`` takes what ``faceclean.resolve`` does: a learned model (.npz checkpoint or
exported .onnx step graph), a preset (file or shipped name) or a method name, with
settings; level-mapping settings (gain, offset, curve, clamp, off) map the raw values
before the cleaner. Nothing here imports torch.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from faceclean import filters
from faceclean.adjust import apply_levels
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, canonical
from faceclean.errors import FacecleanError
from faceclean.filters.rotation import clean_pose
from faceclean.resolve import BACKENDS, Choice, resolve

__all__ = ["BACKENDS", "Cleaner"]


class Cleaner:
    """A cleaner for ``streams`` faces stepped together, plus whole-clip cleaning.

    ``source`` says what was loaded (method, file, settings).
    """

    def __init__(self, choice: Choice, *, streams: int = 1, names: Sequence[str] = ARKIT52) -> None:
        if int(streams) < 1:
            raise FacecleanError(f"streams must be >= 1 (got {streams})")
        self.streams = int(streams)
        self.names = tuple(names)
        self.choice = choice
        self.source = choice.source
        self.cleaner: filters.Stepper = choice.build(self.names)  # the streaming cleaner inside
        self._levels = choice.adjust(self.names).levels(self.names) if choice.levels else None
        self._shape = (len(self.names),) if self.streams == 1 else (self.streams, len(self.names))
        self.reset()

    @classmethod
    def load(
        cls,
        model: str | os.PathLike | None = None,
        *,
        settings: Iterable[str] | Mapping[str, Any] = (),
        streams: int = 1,
        backend: str | None = None,
        names: Sequence[str] = ARKIT52,
    ) -> Cleaner:
        """Load a cleaner; ``model`` None is the shipped default (see faceclean.resolve).

        backend: "numpy" (the torch-free runtime) or "onnx" (ONNX Runtime) for learned
        models; None picks numpy for .npz and onnx for .onnx.
        """
        return cls(resolve(model, settings, backend=backend), streams=streams, names=names)

    @property
    def offline(self) -> bool:
        """True for non-causal cleaners (gaussian, savgol): ``clean`` only."""
        return self.cleaner.offline

    @property
    def state_bytes(self) -> int | None:
        """Bytes of state per stream, where the cleaner reports it."""
        return getattr(self.cleaner, "state_bytes", None)

    def reset(self) -> None:
        """Forget every stream's past."""
        self.cleaner.reset()

    def step(self, x: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        """Clean the newest frame: x (M,) and t s, or x (streams, M) and t (streams,)."""
        x = np.asarray(x)
        if x.shape != self._shape:
            raise FacecleanError(f"frame shape {x.shape}, expected {self._shape}")
        if self.streams > 1 and np.shape(t) != (self.streams,):
            raise FacecleanError(f"t shape {np.shape(t)}, expected ({self.streams},)")
        if self.offline:
            raise FacecleanError(f"{self.source} is offline (non-causal): use clean()")
        if self._levels is not None:
            x = apply_levels(self._levels, x.astype(np.float64))
        return self.cleaner.step(x, t)

    def clean(self, anim: Animation) -> Animation:
        """A cleaned copy of a whole clip: its blendshape channels cleaned, its head/eye
        angles (``meta["pose"]``) by the rotation filter, every other column as it was.
        Resets the streams."""
        cols = [j for j, n in enumerate(anim.names) if canonical(n) is not None]
        if not cols:
            raise FacecleanError("the animation has no blendshape channels to clean")
        names = [anim.names[j] for j in cols]
        values = anim.values[:, cols]
        if self.choice.levels:
            values = self.choice.adjust(names).apply(values, names)
        cleaned = self.choice.build(names).clean(Animation(anim.times, values, names))
        out = anim.values.copy()
        out[:, cols] = cleaned.values
        self.reset()
        return clean_pose(anim.with_values(out), self.choice.build_pose)

    def __repr__(self) -> str:
        return f"Cleaner({self.source!r}, streams={self.streams})"
