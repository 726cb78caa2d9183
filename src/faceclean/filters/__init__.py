"""Every cleaner by name. ``make("one-euro", {"min_cutoff": 1.0})`` builds one.

Method name -> "module:Class". Classes take their parameters as keyword arguments
(physical units: seconds, Hz) plus ``names`` (the channel names, for per-group values).
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any

from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.filters.base import Cleaner, OfflineCleaner, StreamCleaner

METHODS: dict[str, str] = {
    "ema": "faceclean.filters.ema:Ema",
    "one-euro": "faceclean.filters.one_euro:OneEuro",
    "kalman": "faceclean.filters.kalman:Kalman",
    "gaussian": "faceclean.filters.gaussian:Gaussian",
    "savgol": "faceclean.filters.savgol:SavGol",
    "adaptive": "faceclean.learned.adaptive:Adaptive",
    "lstm": "faceclean.learned.cleaner:Learned",
    "fc": "faceclean.learned.derivative_net:FullyConnected",
    "gbt": "faceclean.learned.derivative_net:BoostedTrees",
}

__all__ = [
    "METHODS",
    "Cleaner",
    "OfflineCleaner",
    "StreamCleaner",
    "cleaner_class",
    "default_method",
    "make",
]


def cleaner_class(method: str) -> type[Cleaner]:
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
    tuned: bool = True,
) -> Cleaner:
    """Build a cleaner; a bad parameter name or value is a one-line FacecleanError.

    A method named without parameters gets its shipped tuned preset
    (``presets/<method>.json``) when one exists, so users and comparisons meet the
    tuned filter, never the constructor's defaults; ``tuned=False`` gives the defaults.
    """
    if tuned and not params:
        from faceclean.settings import PRESETS

        if (PRESETS / f"{method}.json").is_file():
            from faceclean.filters import presets

            return presets.build(method, names)
    cls = cleaner_class(method)
    try:
        return cls(**(params or {}), names=tuple(names))
    except TypeError as e:
        raise FacecleanError(f"{method}: bad parameters ({e})") from None


def default_method() -> str:
    """The shipped default: the learned adaptive cleaner when its model ships, else tuned
    One Euro."""
    from faceclean.settings import MODELS

    return "adaptive" if (MODELS / "default.npz").is_file() else "one-euro"
