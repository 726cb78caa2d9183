"""Constant-velocity Kalman filter per channel, vectorised, exact for any dt.

State per channel: position p (weight) and velocity v (weight/s). The motion model is a
continuous white-noise acceleration with spectral density ``q`` ((weight/s^2)^2 / Hz =
weight^2 / s^3); its exact discretisation over a step of dt seconds is

    F = [[1, dt], [0, 1]],   Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]].

The measurement is the position with noise std ``r`` (weight units): H = [1, 0], R = r^2.
The covariance P = [[a, b], [b, c]] is kept as three (S, M) arrays. On (re)start,
p = x, v = 0, P = diag(r^2, V0_STD^2).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.filters.base import State, StreamCleaner
from faceclean.filters.params import per_channel

V0_STD = 1.0  # weight/s; prior std of the velocity at a (re)start


class Kalman(StreamCleaner):
    """Constant-velocity Kalman filter: acceleration density ``q``, measurement std ``r``."""

    name = "kalman"
    PER_CHANNEL = ("q", "r")  # per-channel settings

    def __init__(
        self,
        *,
        q: float | Sequence[float] = 5.0,
        r: float | Sequence[float] = 0.02,
        names: Sequence[str] = ARKIT52,
    ) -> None:
        self.names = tuple(names)
        self.q = per_channel(q, names, "kalman q")
        self.r = per_channel(r, names, "kalman r")
        self.reset()

    def _start(self, x: np.ndarray) -> State:
        zero = np.zeros_like(x)
        a = np.broadcast_to(self.r**2, x.shape).copy()
        c = np.full_like(x, V0_STD**2)
        return x.copy(), zero, a, zero.copy(), c

    def _compiled(self):
        from faceclean.filters import compiled

        return compiled.kalman(len(self.names), self.q, self.r)

    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        p, v, a, b, c = state  # (S, M) each
        q = self.q
        # Predict: x = F x, P = F P F^T + Q.
        p = p + dt * v
        a = a + dt * (2.0 * b + dt * c) + q * dt**3 / 3.0
        b = b + dt * c + q * dt**2 / 2.0
        c = c + q * dt
        # Update with the measured position.
        s = a + self.r**2
        k0, k1 = a / s, b / s
        innov = x - p
        p = p + k0 * innov
        v = v + k1 * innov
        a, b, c = (1.0 - k0) * a, (1.0 - k0) * b, c - k1 * b
        return (p, v, a, b, c), p
