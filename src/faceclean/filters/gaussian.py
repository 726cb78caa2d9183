"""Gaussian smoothing, offline (non-causal): the paper's second baseline.

The kernel lives in time, so irregular timestamps and dropped frames are handled:

    y[n] = sum_m w_nm x[m] / sum_m w_nm,   w_nm = exp(-(t[m] - t[n])^2 / (2 sigma^2)),

over frames within TRUNCATE sigma of t[n]. Near the ends of a clip the weights are
renormalised over the frames that exist (no padding). ``sigma_frames`` (the paper's
σ 1 and 5) is converted to seconds with the clip's median frame step, so on a regular
grid it is the ordinary frame-based Gaussian filter. ``sigma`` may be per channel (M,).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.filters.base import OfflineCleaner
from faceclean.filters.params import set_seconds_or
from faceclean.filters.window import median_dt, reach, shifted

SIGMA = 0.03  # s; default (about 2 frames at 60 fps)
TRUNCATE = 4.0  # kernel support, in sigmas


class Gaussian(OfflineCleaner):
    """Gaussian smoothing over the whole clip: ``sigma`` seconds or ``sigma_frames`` frames."""

    name = "gaussian"
    PER_CHANNEL = ("sigma", "sigma_frames")  # per-channel settings

    def __init__(
        self,
        *,
        sigma: float | Sequence[float] | None = None,
        sigma_frames: float | Sequence[float] | None = None,
        names: Sequence[str] = ARKIT52,
    ) -> None:
        set_seconds_or(
            self, names, ("sigma", sigma, SIGMA), ("sigma_frames", sigma_frames, "frames")
        )
        self.reset()

    def _smooth(self, times: np.ndarray, values: np.ndarray) -> np.ndarray:
        if self.sigma_frames is not None:
            sigma = self.sigma_frames * median_dt(times)  # s
        else:
            sigma = self.sigma
        sigma = np.broadcast_to(sigma, values.shape[1:])  # (M,) s
        support = TRUNCATE * sigma * (1 + 1e-9)  # (M,) s; the tolerance keeps the last tap
        k_max = reach(times, float(support.max()))
        num = np.zeros_like(values)
        den = np.zeros_like(values)
        for k in range(-k_max, k_max + 1):
            m, ok = shifted(times, k)
            d = (times[m] - times)[:, None]  # (N, 1) s
            w = np.exp(-0.5 * (d / sigma) ** 2) * (ok[:, None] & (np.abs(d) <= support))
            num += w * values[m]
            den += w
        return num / den
