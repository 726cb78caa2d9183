"""Savitzky-Golay smoothing, offline (non-causal), on real timestamps.

Each output is the value at t[n] of the polynomial of degree ``polyorder`` fitted by
least squares to the frames within +-window/2 seconds of t[n]. On a regular grid this is
``scipy.signal.savgol_filter`` away from the ends; with irregular or dropped frames the
fit uses the frames' real times (a local polynomial regression), so it stays correct.
Near the ends and around gaps the window holds fewer frames; when it cannot determine
the polynomial, the minimum-norm least-squares fit is used (one frame: itself).
``window_frames`` (odd) is converted to seconds with the clip's median frame step.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.filters.base import OfflineCleaner
from faceclean.filters.params import per_channel
from faceclean.filters.window import median_dt, reach, shifted

WINDOW = 0.15  # s; default window (9 frames at 60 fps)
POLYORDER = 2


class SavGol(OfflineCleaner):
    """Local polynomial smoothing: ``window`` seconds (or ``window_frames``), ``polyorder``."""

    name = "savgol"

    def __init__(
        self,
        *,
        window: float | None = None,
        window_frames: int | None = None,
        polyorder: int = POLYORDER,
        names: Sequence[str] = ARKIT52,
    ) -> None:
        if window is not None and window_frames is not None:
            raise FacecleanError("savgol: give window (seconds) or window_frames, not both")
        self.names = tuple(names)
        if window_frames is not None:
            w = float(per_channel(window_frames, (), "savgol window_frames"))
            if w != int(w) or int(w) % 2 == 0:
                raise FacecleanError("savgol window_frames must be an odd whole number")
            self.window_frames: int | None = int(w)
            self.window = None
        else:
            self.window_frames = None
            self.window = float(per_channel(WINDOW if window is None else window, (), "window"))
        order = float(per_channel(polyorder, (), "savgol polyorder", open_low=False, high=6))
        if order != int(order):
            raise FacecleanError("savgol polyorder must be a whole number from 0 to 6")
        self.polyorder = int(order)
        self.reset()

    def _smooth(self, times: np.ndarray, values: np.ndarray) -> np.ndarray:
        if self.window_frames is not None:
            half = (self.window_frames - 1) / 2 * median_dt(times) * (1 + 1e-6)  # s
        else:
            half = self.window / 2
        p = self.polyorder
        n, m_ch = values.shape
        s = np.zeros((n, 2 * p + 1))  # sum of u^j, u = (t[m] - t[n]) / half in [-1, 1]
        b = np.zeros((p + 1, n, m_ch))  # sum of u^j x[m]
        for k in range(-reach(times, half), reach(times, half) + 1):
            m, ok = shifted(times, k)
            u = (times[m] - times) / half
            inside = ok & (np.abs(u) <= 1.0)
            powers = np.where(inside[:, None], u[:, None] ** np.arange(2 * p + 1), 0.0)
            s += powers
            b += powers[:, : p + 1].T[:, :, None] * values[m][None]
        a = s[:, np.arange(p + 1)[:, None] + np.arange(p + 1)]  # (N, p+1, p+1) Hankel
        e0 = np.linalg.pinv(a, rcond=1e-10, hermitian=True)[:, 0, :]  # (N, p+1)
        y = np.einsum("nj,jnm->nm", e0, b)
        # a polynomial overshoots a blink's edge (a weight under 0 bends the face the other
        # way): no output leaves the range its channel's input spans
        seen = ~np.isnan(values)
        lo = np.where(seen, values, np.inf).min(axis=0)  # (M,); a column with none: no bound
        hi = np.where(seen, values, -np.inf).max(axis=0)
        return np.clip(y, np.where(seen.any(axis=0), lo, -np.inf), np.where(seen.any(axis=0), hi,
                                                                              np.inf))  # fmt: skip
