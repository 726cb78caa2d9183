"""faceclean: real-time cleaning of facial-capture blendshape animation.

The public face: ``Animation``, ``load``, ``save``, ``Cleaner``. Nothing here imports torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.io import load, save

if TYPE_CHECKING:
    from faceclean.cleaner import Cleaner

__all__ = ["Animation", "Cleaner", "FacecleanError", "load", "save"]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    if name == "Cleaner":  # the runtime facade (faceclean/cleaner.py)
        from faceclean.cleaner import Cleaner

        return Cleaner
    raise AttributeError(name)
