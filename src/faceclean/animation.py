"""Animation: the one in-memory type every reader returns and every writer takes."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52, canonical, channel_key

MIN_DT = 1e-12  # s; a step this small or smaller is a duplicate (the cleaners' rule 4)
MAX_ABS = 1e6  # |value| above this is no value: non-finite to the cleaners (rule 2)
MAX_MADE = 4_000_000  # frames a made take (synth, corrupt) has at most: 18 h at 60 Hz, 1.7 GB


@dataclass(eq=False)
class Animation:
    """Blendshape weights over time.

    times:  (N,) float64, seconds, non-decreasing in well-formed input.
    values: (N, M) float64. A row that is all NaN is a missing frame (tracking loss):
            kept in place, never cleaned, written back as the source had it.
    names:  (M,) channel names as the source spelled them (``canonical`` maps them).
    meta:   whatever the source format carried that must go back out unchanged
            (keys are owned by the format module that wrote them).
    """

    times: np.ndarray
    values: np.ndarray
    names: tuple[str, ...]
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        self.values = np.asarray(self.values, dtype=np.float64)
        if self.values.ndim == 1:
            self.values = self.values.reshape(len(self.times), -1)
        self.names = tuple(str(n) for n in self.names)
        if self.values.shape != (len(self.times), len(self.names)):
            raise ValueError(
                f"values {self.values.shape} do not match {len(self.times)} times "
                f"x {len(self.names)} names"
            )

    @property
    def n_frames(self) -> int:
        return len(self.times)

    @property
    def n_channels(self) -> int:
        return len(self.names)

    @property
    def valid(self) -> np.ndarray:
        """(N,) bool: frames that carry values (not tracking loss)."""
        if not self.n_channels:
            return np.ones(self.n_frames, bool)
        ok = ~np.isnan(self.values[:, 0])  # the first value read: the frame is valid
        lost = np.flatnonzero(~ok)  # the rest: valid where any value is read
        ok[lost] = ~np.all(np.isnan(self.values[lost]), axis=1)
        return ok

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0]) if self.n_frames > 1 else 0.0

    @property
    def rate(self) -> float:
        """Median frame rate in Hz over valid consecutive frames (0 if unknown). Steps of
        MIN_DT or less are duplicates, not a rate of 1e300 Hz."""
        dt = np.diff(self.times[self.valid])
        dt = dt[dt > MIN_DT]
        return float(1.0 / np.median(dt)) if len(dt) else 0.0

    def channel(self, name: str) -> np.ndarray:
        """(N,) values of one channel, by any accepted spelling."""
        want = channel_key(name)
        for j, n in enumerate(self.names):
            if n == name or canonical(n) == want:
                return self.values[:, j]
        raise KeyError(name)

    def with_values(self, values: np.ndarray) -> Animation:
        """A copy with new values (N, M); times, names and meta carried over."""
        return Animation(self.times.copy(), values, self.names, dict(self.meta))

    def arkit(self, names: Sequence[str] = ARKIT52) -> tuple[np.ndarray, np.ndarray]:
        """Values in the order ``names`` (canonical): ((N, len(names)), present (len(names),)).

        Channels the source lacks are zeros and marked absent.
        """
        cmap = ChannelMap(names, self.names)
        out = np.zeros((self.n_frames, len(names)))
        out[:, cmap.have] = self.values[:, cmap.cols]
        present = cmap.src >= 0
        out[~self.valid] = np.nan
        return out, present

    @classmethod
    def from_arkit(cls, times: np.ndarray, values: np.ndarray) -> Animation:
        """An ARKit-52 animation from (N,) times and (N, 52) values."""
        return cls(times, values, ARKIT52)
