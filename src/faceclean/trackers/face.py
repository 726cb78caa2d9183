"""MediaPipe Face Landmarker on a video or a camera: scores and the head's rotation.

``FaceTracker(model)`` is MediaPipe in VIDEO mode with the facial transformation matrix
on. It looks for up to ``MAX_FACES`` faces and follows one (``Follow``): the largest when a
face is first found, then in each frame the one nearest where the followed face was last
seen; ``crowd`` says once, in one line, when more than one face was in view and which
one is followed. ``track(rgb, t)`` gives the 51
ARKit scores MediaPipe has (``NAMES``: no ``tongueOut``) and the head's (yaw, pitch, roll)
in radians, Live Link's convention (faceclean.pose: +yaw turns the face to the subject's
right, +pitch down), or None when no face is found: a lost face is a missing frame,
never a guess. ``track_video(path)`` tracks a whole file into an ``Animation`` on the
video's own times, the head angles in ``meta["pose"]`` as a Live Link take carries them.

Rotation: MediaPipe's matrix maps its canonical face (right-handed: +X the subject's left
as the camera sees it, +Y up, +Z out of the face) into camera space. Live Link's frame is
that one with X mirrored (faceclean.pose), so its rotation is ``S R S``, S = diag(-1, 1,
1), read in the Y-X-Z order: yaw = atan2(-R02, R22), pitch = asin(-R12), roll =
atan2(-R10, R11). The matrix's columns are normalised first (it may carry a scale).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from faceclean.animation import Animation
from faceclean.channel_map import ChannelMap
from faceclean.errors import FacecleanError
from faceclean.synthetic.tracker import NAMES, landmarker

HEAD = ("HeadYaw", "HeadPitch", "HeadRoll")  # the angles a tracked take carries, rad
MAX_FACES = 2  # faces MediaPipe looks for: a second one is seen, so the choice is ours


def head_angles(matrix: np.ndarray) -> np.ndarray:
    """(3,) Live Link yaw, pitch, roll (rad) of MediaPipe's (4, 4) facial transformation."""
    r = np.asarray(matrix, np.float64)[:3, :3]
    r = r / np.linalg.norm(r, axis=0, keepdims=True)  # columns: drop any scale
    yaw = np.arctan2(-r[0, 2], r[2, 2])
    pitch = np.arcsin(np.clip(-r[1, 2], -1.0, 1.0))
    roll = np.arctan2(-r[1, 0], r[1, 1])
    return np.array([yaw, pitch, roll])


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
    time several faces were in view (None until then)."""

    def __init__(self) -> None:
        self.last: np.ndarray | None = None  # (2,) px, the followed face's last centre
        self.crowd: str | None = None

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
        self.last = centre[i]
        return i


class FaceTracker:
    """MediaPipe Face Landmarker, VIDEO mode, one face followed, with the head's rotation.
    ``on_crowd(line)`` is called once, the first time several faces are in view."""

    def __init__(self, model: str | os.PathLike | None = None,
                 on_crowd: Callable[[str], None] | None = None) -> None:  # fmt: skip
        self._marker = landmarker(model_path(model), video=True, blendshapes=True, pose=True,
                                  extra="track", faces=MAX_FACES)  # fmt: skip
        self._last_ms = -1
        self._map: tuple[tuple[str, ...], ChannelMap] | None = None
        self.follow = Follow()
        self._on_crowd = on_crowd

    @property
    def crowd(self) -> str | None:
        """The line said when several faces were first in view, or None."""
        return self.follow.crowd

    def track(self, rgb: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray] | None:
        """((51,) scores in ``NAMES`` order, (3,) yaw/pitch/roll rad) of an (H, W, 3)
        uint8 RGB frame at ``t`` s, or None (no face). VIDEO mode wants increasing whole
        milliseconds: ``t`` is rounded and forced to increase."""
        import mediapipe as mp

        ms = max(int(round(t * 1000.0)), self._last_ms + 1)
        self._last_ms = ms
        image = mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(rgb))
        result = self._marker.detect_for_video(image, ms)
        if not result.face_blendshapes:
            return None
        h, w = rgb.shape[:2]
        faces = [np.array([(p.x * w, p.y * h) for p in lm]) for lm in result.face_landmarks]
        said = self.follow.crowd
        k = self.follow.choose(faces, t, w)  # which face, of those found
        if said is None and self.follow.crowd is not None and self._on_crowd is not None:
            self._on_crowd(self.follow.crowd)
        cats = result.face_blendshapes[k]
        names = tuple(c.category_name for c in cats)
        if self._map is None or self._map[0] != names:
            self._map = (names, ChannelMap(NAMES, names))
        cmap = self._map[1]
        scores = np.full(len(NAMES), np.nan)
        scores[cmap.have] = np.array([c.score for c in cats], np.float64)[cmap.cols]
        angles = np.full(3, np.nan)
        if len(result.facial_transformation_matrixes) > k:
            angles = head_angles(result.facial_transformation_matrixes[k])
        return scores, angles

    def close(self) -> None:
        self._marker.close()

    def __enter__(self) -> FaceTracker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
            found = tracker.track(rgb, t)
            times.append(t)
            rows.append(lost if found is None else found[0])
            angles.append(np.full(3, np.nan) if found is None else found[1])
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
