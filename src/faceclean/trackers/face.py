"""MediaPipe on a video or a camera: ``faceclean track``'s tracker and a whole video tracked.

``FaceTracker(model)`` is the one MediaPipe tracker (trackers/mediapipe.py ``Tracker``, a
faceclean.tracking ``Tracker``) built for ``track``: the facial transformation matrix on,
so ``read(rgb, t)`` gives, beside the 51 ARKit scores MediaPipe has (``NAMES``: no
``tongueOut``) and the landmarks, the head's (yaw, pitch, roll) in radians, Live Link's
convention (faceclean.pose: +yaw turns the face to the subject's right, +pitch down;
``head_angles``), or None when no face is found: a lost face is a missing frame, never a
guess. It looks for up to ``MAX_FACES`` faces and follows one (``Follow``): the largest
when a face is first found, then in each frame the one nearest where the followed face
was last seen; ``crowd`` says once, in one line, when more than one face was in view and
which one is followed. ``track_video(path)`` tracks a whole file into an ``Animation`` on
the video's own times, the head angles in ``meta["pose"]`` as a Live Link take carries
them.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.trackers.mediapipe import NAMES, Tracker

HEAD = ("HeadYaw", "HeadPitch", "HeadRoll")  # the angles a tracked take carries, rad
MAX_FACES = 2  # faces MediaPipe looks for: a second one is seen, so the choice is ours


def model_path(path: str | os.PathLike | None = None) -> Path:
    """The Face Landmarker bundle: ``path``, else ``settings.tracker_model()``."""
    from faceclean import settings

    found = Path(path) if path is not None else settings.tracker_model()
    if found is None or not found.is_file():
        raise FacecleanError(
            f"no face landmarker model at {found}: set FACECLEAN_TRACKER_MODEL to "
            "MediaPipe's face_landmarker.task"
        )
    return found


class Follow:
    """Which of the faces in a frame is followed: the largest (landmark box area, px^2)
    when none was followed yet, else the one whose box centre is nearest the followed
    face's last centre (px). A frame without a face keeps the last centre, so a face that
    comes back near where it left is the same one. ``crowd``: the one line said the first
    time several faces were in view (None until then), also given to ``on_crowd(line)``."""

    def __init__(self, on_crowd: Callable[[str], None] | None = None) -> None:
        self.last: np.ndarray | None = None  # (2,) px, the followed face's last centre
        self.crowd: str | None = None
        self._on_crowd = on_crowd

    def choose(self, faces: list[np.ndarray], t: float, width: int) -> int:
        """Index into ``faces`` (each (L, 2) landmark px) of the followed one, at ``t`` s
        in a frame ``width`` px wide."""
        lo = np.array([f.min(0) for f in faces])  # (F, 2) px
        hi = np.array([f.max(0) for f in faces])
        centre = (lo + hi) / 2
        first = self.last is None
        if first:
            i = int(np.argmax(np.prod(hi - lo, axis=1)))
        else:
            i = int(np.argmin(np.linalg.norm(centre - self.last, axis=1)))
        if len(faces) > 1 and self.crowd is None:
            x = float(centre[i, 0])
            side = "left" if x < width / 3 else "right" if x > 2 * width / 3 else "middle"
            rule = "the largest" if first else "the one followed so far"
            self.crowd = (f"{len(faces)} faces in view at {t:.2f} s: tracking {rule}, on the "
                          f"{side} of the picture (x {x:.0f} of {width} px, "
                          f"{float(hi[i, 0] - lo[i, 0]):.0f} px wide); the others are "
                          "ignored")  # fmt: skip
            if self._on_crowd is not None:
                self._on_crowd(self.crowd)
        self.last = centre[i]
        return i


class FaceTracker(Tracker):
    """MediaPipe (trackers/mediapipe.py ``Tracker``), VIDEO mode, up to ``MAX_FACES`` looked
    for and one followed (``Follow``), with the head's rotation (``Reading.pose``, (3,) rad,
    NaN when MediaPipe gives no matrix). ``on_crowd(line)`` is called once, the first time
    several faces are in view."""

    def __init__(self, model: str | os.PathLike | None = None,
                 on_crowd: Callable[[str], None] | None = None) -> None:  # fmt: skip
        self.follow = Follow(on_crowd)
        super().__init__(model_path(model), pose=True, faces=MAX_FACES,
                         choose=self.follow.choose, extra="track")  # fmt: skip

    @property
    def crowd(self) -> str | None:
        """The line said when several faces were first in view, or None."""
        return self.follow.crowd


def track_video(
    path: str | os.PathLike,
    model: str | os.PathLike | None = None,
    progress: Callable[[int, int], None] | None = None,
    on_crowd: Callable[[str], None] | None = None,
) -> Animation:
    """A video file tracked into a take: (N, 51) scores on the video's own times (s from
    its first frame), all-NaN rows where no face was found, ``meta["pose"]`` (N, 3) head
    angles (rad, NaN where lost). ``progress(done, total)`` after each frame (total: the
    container's frame count, 0 when unknown); ``on_crowd(line)`` once if several faces were
    in view (``Follow``: which one is tracked). No face in any frame is refused."""
    from faceclean.trackers.video import Video

    times, rows, angles = [], [], []
    lost = np.full(len(NAMES), np.nan)
    with Video(path) as video, FaceTracker(model, on_crowd) as tracker:
        for rgb, t in video:
            found = tracker.read(rgb, t)
            times.append(t)
            rows.append(lost if found is None else found.scores)
            angles.append(np.full(3, np.nan) if found is None else found.pose)
            if progress is not None:
                progress(len(times), video.frame_count)
    values = np.array(rows)  # (N, 51)
    if not np.isfinite(values).any():
        raise FacecleanError(f"{path}: no face found in any of its {len(times)} frames")
    t = np.array(times)
    meta = {
        "format": "livelink",
        "pose": np.array(angles),  # (N, 3) rad
        "pose_names": HEAD,
    }
    return Animation(t - t[0], values, NAMES, meta)
