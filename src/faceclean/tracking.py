"""The tracker interface: what a face tracker takes and what it gives, whichever it is.

A tracker takes one video frame, an (H, W, 3) uint8 RGB image, at ``t`` seconds (times
increase within a stream, as a video's or a camera's frames do), and gives a ``Reading``
of the face it follows: scores on its named channels (``names``; ARKit's channels under
their canonical names, faceclean.channels), and where it has them the face's landmarks
and the head's rotation. No face found is None: a lost face is a missing frame, never a
guess. A tracker keeps state from frame to frame (it follows a face) and holds a model:
``close()`` it when the stream ends. ``name`` says what made the scores, version
included (a pair's record names it).

MediaPipe's Face Landmarker implements it, once (trackers/mediapipe.py ``Tracker``): the
pairs engine feeds a tracker rendered frames through this interface alone (``scores``), so
a second tracker plugs in there (synthetic/engine.py ``Worker(tracker=...)``);
``faceclean track`` reads a video or a camera through it (trackers/face.py
``FaceTracker``: the same MediaPipe, one of two faces followed, with the head's pose).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np


class Reading(NamedTuple):
    """What a tracker read off one frame."""

    scores: np.ndarray  # (C,) in the tracker's ``names`` order, NaN: not read this frame
    # (L, 3) px: x right, y down from the frame's top left, z toward the camera negative
    # (x's scale); None: the tracker gives none
    landmarks: np.ndarray | None = None
    pose: np.ndarray | None = None  # (3,) head yaw, pitch, roll, rad (faceclean.pose's)


@runtime_checkable
class Tracker(Protocol):
    """A face tracker (module docstring)."""

    names: tuple[str, ...]  # the channels of ``Reading.scores``

    @property
    def name(self) -> str:
        """What made the scores, version included ("mediapipe 0.10.14 face_landmarker")."""
        ...

    def read(self, frame: np.ndarray, t: float) -> Reading | None:
        """The face in an (H, W, 3) uint8 RGB ``frame`` at ``t`` s, or None (no face)."""
        ...

    def close(self) -> None:
        """Let go of the model; the tracker is not used after."""
        ...


def scores(tracker: Tracker, frames: Iterable[tuple[np.ndarray, float]]) -> np.ndarray:
    """(N, C) ``tracker``'s scores of N (frame, t s) in turn, in ``tracker.names`` order;
    a row of NaN where it found no face."""
    rows = []
    for frame, t in frames:
        reading = tracker.read(frame, t)
        rows.append(np.full(len(tracker.names), np.nan) if reading is None else reading.scores)
    return np.array(rows, np.float64).reshape(len(rows), len(tracker.names))
