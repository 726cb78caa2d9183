"""Cleaner parameters: a scalar for every channel, or one value per channel (M,)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from faceclean.errors import FacecleanError


def per_channel(
    value: Any,
    names: Sequence[str],
    what: str,
    *,
    low: float | None = 0.0,
    high: float | None = None,
    open_low: bool = True,
) -> np.ndarray:
    """``value`` as float64: 0-d for a scalar (fits any M), (M,) for a per-channel list.

    Raises FacecleanError (one line) for a wrong length, a non-number or a value outside
    (low, high] (``open_low``) or [low, high].
    """
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise FacecleanError(f"{what} must be a number or a list of numbers") from None
    if isinstance(value, bool) or a.dtype == bool:
        raise FacecleanError(f"{what} must be a number, not a boolean")
    if a.ndim > 1 or (a.ndim == 1 and len(a) != len(names)):
        raise FacecleanError(f"{what} has shape {a.shape}: give a scalar or {len(names)} values")
    if not np.isfinite(a).all():
        raise FacecleanError(f"{what} must be finite")
    if low is not None and ((a <= low).any() if open_low else (a < low).any()):
        raise FacecleanError(f"{what} must be {'>' if open_low else '>='} {low}")
    if high is not None and (a > high).any():
        raise FacecleanError(f"{what} must be <= {high}")
    return a
