"""A decoded face frame: what every relay codec turns bytes into and back.

Codecs are pure: ``Decoder.feed(datagram) -> Frame | None`` and
``Encoder.encode(frame) -> bytes``. A datagram a decoder cannot read raises
:class:`Malformed` (and nothing else); the relay counts it and moves on.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from faceclean.channels import POSE
from faceclean.errors import FacecleanError

# Live Link Face's 9 head and eye angles (radians), after the 52 blendshapes.
POSE_NAMES: tuple[str, ...] = POSE
Timecode = tuple[int, float, int, int]  # frame number, sub-frame, rate numerator, denominator


class Malformed(FacecleanError):
    """A datagram that is not a packet of the expected protocol (counted, then skipped)."""


@dataclass(slots=True)
class Frame:
    """One frame of a live stream.

    names:       (M,) channel names as the sender spelled them (may be empty: a
                 datagram that only carries passthrough messages).
    values:      (M,) float64 weights in [0, 1] (non-finite values are possible).
    t:           s, the sender's timestamp, or None when the packet has none.
    pose:        (9,) Live Link head/eye angles (``POSE_NAMES``), rad, or None; NaN
                 where the source sent no such angle (a VMC Head bone without eyes).
    passthrough: raw OSC elements (messages or bundles) to forward unchanged.
    subject, device: Live Link subject name and device id, or None.
    timecode:    the sender's own (frame number, sub-frame, rate numerator, rate
                 denominator) (Live Link), kept as it came; None when it sent none.
    positions:   VMC bone name -> its (x, y, z) local position as received, for the
                 bones the pose came from (sent back with the cleaned rotation).
    """

    names: tuple[str, ...]
    values: np.ndarray
    t: float | None = None
    pose: np.ndarray | None = None
    passthrough: tuple[bytes, ...] = ()
    subject: str | None = None
    device: str | None = None
    timecode: Timecode | None = None
    positions: dict[str, tuple[float, float, float]] | None = None

    @property
    def is_face(self) -> bool:
        """True when the frame carries blendshape weights (not only passthrough)."""
        return len(self.names) > 0


class Decoder(Protocol):
    def feed(self, data: bytes) -> Frame | None:
        """Decode one datagram: a complete frame, or None (nothing complete yet)."""
        ...


class Encoder(Protocol):
    def encode(self, frame: Frame) -> bytes:
        """One datagram carrying ``frame``."""
        ...
