"""Windows in time over irregularly sampled frames, for the offline cleaners.

Frames are at increasing times t (N,). Rather than a kernel in frames, each output n
sees the frames m with |t[m] - t[n]| <= half_width seconds. ``offsets`` gives the frame
offsets k = m - n that can fall inside, so a filter loops over k (a few dozen) with
vectorised (N, M) work instead of looping over frames.
"""

from __future__ import annotations

import numpy as np


def reach(times: np.ndarray, half_width: float) -> int:
    """Largest frame offset k with |t[n + k] - t[n]| <= half_width for some n."""
    if len(times) < 2:
        return 0
    right = np.searchsorted(times, times + half_width, side="right") - 1  # (N,)
    return int(np.max(right - np.arange(len(times))))


def shifted(times: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Index n + k clipped into range, and the mask (N,) of n where n + k exists."""
    n = np.arange(len(times))
    m = n + k
    ok = (m >= 0) & (m < len(times))
    return np.clip(m, 0, len(times) - 1), ok


def median_dt(times: np.ndarray) -> float:
    """Median frame step in seconds (1/60 s when there is none to measure)."""
    d = np.diff(times)
    d = d[d > 0]
    return float(np.median(d)) if len(d) else 1.0 / 60.0
