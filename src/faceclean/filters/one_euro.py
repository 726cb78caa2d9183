"""The One Euro filter (Casiez, Roussel, Vogel, CHI 2012), causal, on real timestamps.

Per channel, with dt the real time step and alpha(fc) = 1 / (1 + 1 / (2 pi fc dt)):

    dx  = (x - y_prev) / dt                   # slope from the previous *filtered* value
    edx = edx_prev + alpha(d_cutoff) (dx - edx_prev)
    fc  = min_cutoff + beta |edx|             # Hz; faster motion, less smoothing
    y   = y_prev + alpha(fc) (x - y_prev)

Units: cut-offs in Hz, beta in Hz per (weight unit / s). Slow motion is low-passed at
``min_cutoff`` (less jitter), fast motion such as a blink opens the filter (less lag).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.filters.base import State, StreamCleaner
from faceclean.filters.params import per_channel

DT_MIN = 1e-6  # s; a smaller step is taken as this one (keeps dx finite)


def alpha(cutoff: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Smoothing factor of a first-order low-pass at ``cutoff`` Hz for a step of dt s."""
    return 1.0 / (1.0 + 1.0 / (2.0 * np.pi * cutoff * dt))


class OneEuro(StreamCleaner):
    """One Euro filter: ``min_cutoff`` Hz, ``beta``, ``d_cutoff`` Hz (scalars or (M,))."""

    name = "one-euro"
    PER_CHANNEL = ("min_cutoff", "beta", "d_cutoff")  # per-channel settings

    def __init__(
        self,
        *,
        min_cutoff: float | Sequence[float] = 1.5,
        beta: float | Sequence[float] = 3.0,
        d_cutoff: float | Sequence[float] = 1.0,
        names: Sequence[str] = ARKIT52,
    ) -> None:
        self.names = tuple(names)
        self.min_cutoff = per_channel(min_cutoff, names, "one-euro min_cutoff")
        self.beta = per_channel(beta, names, "one-euro beta", open_low=False)
        self.d_cutoff = per_channel(d_cutoff, names, "one-euro d_cutoff")
        self.reset()

    def _start(self, x: np.ndarray) -> State:
        return x.copy(), np.zeros_like(x)

    def _compiled(self):
        from faceclean.filters import compiled

        return compiled.one_euro(len(self.names), self.min_cutoff, self.beta, self.d_cutoff)

    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        y, edx = state  # (S, M) weight, (S, M) weight/s
        dt = np.maximum(dt, DT_MIN)  # (S, 1) s
        dx = (x - y) / dt
        edx = edx + alpha(self.d_cutoff, dt) * (dx - edx)
        cutoff = self.min_cutoff + self.beta * np.abs(edx)
        y = y + alpha(cutoff, dt) * (x - y)
        return (y, edx), y
