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
    if isinstance(value, list | tuple) and any(isinstance(v, list | tuple | dict) for v in value):
        raise FacecleanError(f"{what} must be a number or a flat list of numbers")
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError, RecursionError):  # 10**400: OverflowError
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


def seconds_or(
    method: str,
    names: Sequence[str],
    seconds: tuple[str, Any, float],
    other: tuple[str, Any, str],
    **bounds: Any,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """One setting given in seconds or in another unit, not both (e.g. ema ``tau`` or
    ``gamma``): (the seconds, None) or (None, the other), each from ``per_channel``.

    seconds: (key, value or None, default s); other: (key, value or None, its unit);
    ``bounds`` go to ``per_channel`` for the other one.
    """
    (s_key, s_value, default), (o_key, o_value, unit) = seconds, other
    if s_value is not None and o_value is not None:
        raise FacecleanError(f"{method}: give {s_key} (seconds) or {o_key} ({unit}), not both")
    if o_value is not None:
        return None, per_channel(o_value, names, f"{method} {o_key}", **bounds)
    value = default if s_value is None else s_value
    return per_channel(value, names, f"{method} {s_key}"), None


def set_seconds_or(
    cleaner: Any,
    names: Sequence[str],
    seconds: tuple[str, Any, float],
    other: tuple[str, Any, str],
    **bounds: Any,
) -> None:
    """A constructor's settings for a cleaner set by one width in seconds or in another
    unit (``seconds_or``): ``cleaner.names`` and both attributes, the unused one None."""
    cleaner.names = tuple(names)
    values = seconds_or(cleaner.name, names, seconds, other, **bounds)
    for (key, *_), value in zip((seconds, other), values, strict=True):
        setattr(cleaner, key, value)
