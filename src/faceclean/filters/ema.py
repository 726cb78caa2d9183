"""Exponential smoothing, causal: a time constant in seconds, or the paper's per-frame γ.

dt-aware form (default): alpha = 1 - exp(-dt / tau), y <- y + alpha (x - y); the same
curve sampled at any rate gives the same output (a first-order low-pass, cut-off
1 / (2 pi tau) Hz).

Per-frame form (the paper's baseline, SPEC section 3): y[n] = γ x[n] + (1 - γ) y[n-1]
whatever dt is, so its smoothing depends on the frame rate (γ 0.3 at 60 fps is
tau = -dt / ln(1 - γ) = 47 ms; at 30 fps the same γ is 94 ms).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.filters.base import State, StreamCleaner
from faceclean.filters.params import set_seconds_or

TAU = 0.025  # s; default time constant (a 6.4 Hz low-pass) for 60 fps ARKit data


class Ema(StreamCleaner):
    """Exponential smoothing: ``tau`` seconds (dt-aware) or per-frame ``gamma`` in (0, 1]."""

    name = "ema"
    PER_CHANNEL = ("tau", "gamma")  # per-channel settings

    def __init__(
        self,
        *,
        tau: float | Sequence[float] | None = None,
        gamma: float | Sequence[float] | None = None,
        names: Sequence[str] = ARKIT52,
    ) -> None:
        set_seconds_or(self, names, ("tau", tau, TAU), ("gamma", gamma, "per frame"), high=1.0)
        self.reset()

    def _start(self, x: np.ndarray) -> State:
        return (x.copy(),)

    def _compiled(self):
        from faceclean.filters import compiled

        return compiled.ema(len(self.names), self.gamma, None if self.gamma is not None
                            else self.tau)  # fmt: skip

    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        (y,) = state  # (S, M)
        if self.gamma is not None:
            alpha = self.gamma
        else:
            with np.errstate(over="ignore"):  # a tiny tau: dt/tau = inf, alpha 1 (no smoothing)
                alpha = -np.expm1(-dt / self.tau)
        y = y + alpha * (x - y)
        return (y,), y
