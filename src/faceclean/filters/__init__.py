"""Every cleaner class by name. ``make("one-euro", {"min_cutoff": 1.0})`` builds one.

Method name -> "module:Class". Classes take their parameters as keyword arguments
(physical units: seconds, Hz) plus ``names`` (the channel names, for per-group values).
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Sequence
from typing import Any

from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.filters.base import OfflineCleaner, Stepper, StreamCleaner

METHODS: dict[str, str] = {
    "ema": "faceclean.filters.ema:Ema",
    "one-euro": "faceclean.filters.one_euro:OneEuro",
    "kalman": "faceclean.filters.kalman:Kalman",
    "gaussian": "faceclean.filters.gaussian:Gaussian",
    "savgol": "faceclean.filters.savgol:SavGol",
    "rotation": "faceclean.filters.rotation:Rotation",
    "adaptive": "faceclean.learned.adaptive:Adaptive",
    "lstm": "faceclean.learned.lstm:Learned",
    "fc": "faceclean.learned.derivative_net:FullyConnected",
    "gbt": "faceclean.learned.derivative_net:BoostedTrees",
    "tracker-map": "faceclean.learned.tracker_map:TrackerMap",
}

__all__ = [
    "METHODS",
    "Stepper",
    "OfflineCleaner",
    "StreamCleaner",
    "cleaner_class",
    "make",
    "settings_of",
]


def cleaner_class(method: str) -> type[Stepper]:
    """The class implementing ``method``."""
    if method not in METHODS:
        raise FacecleanError(f"unknown method {method!r} (known: {', '.join(METHODS)})")
    module, cls = METHODS[method].split(":")
    return getattr(importlib.import_module(module), cls)


def make(
    method: str,
    params: dict[str, Any] | None = None,
    *,
    names: Sequence[str] = ARKIT52,
) -> Stepper:
    """The class of ``method`` built with ``params`` (its constructor's defaults for the
    rest); a bad parameter name or value is a one-line FacecleanError. Shipped tuned
    presets, model files and ``--set`` words are ``faceclean.resolve``'s."""
    cls = cleaner_class(method)
    unknown = sorted(set(params or {}) - set(settings_of(cls)))
    if unknown:
        valid = ", ".join(settings_of(cls))
        raise FacecleanError(f"{method}: unknown setting {unknown[0]!r}; valid: {valid}")
    try:
        return cls(**(params or {}), names=tuple(names))
    except TypeError as e:  # a value of the wrong type
        raise FacecleanError(f"{method}: bad parameters ({e})") from None


def settings_of(cls: type[Stepper]) -> list[str]:
    """A cleaner class's settings: its constructor's keywords but ``names``/``weights``."""
    sig = inspect.signature(cls.__init__)
    return [p for p in sig.parameters if p not in ("self", "names", "weights")]
