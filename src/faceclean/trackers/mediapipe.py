"""The one MediaPipe tracker: Google's Face Landmarker in VIDEO mode.

``Tracker(model_path)`` loads the ``face_landmarker.task`` bundle from a file (never
downloaded: ``settings.tracker_model()``, ``../shared/models`` by default). It is a
faceclean.tracking ``Tracker``: ``read(frame, t)`` gives the 51 ARKit scores of one RGB
frame at ``t`` seconds, in MediaPipe's names mapped onto canonical ARKit (``_neutral``
dropped; MediaPipe has no ``tongueOut``), with the 478 landmarks, or None when no face is
found: a lost face is a missing frame. ``track(frame, t)`` gives the scores alone. VIDEO
mode needs increasing integer millisecond timestamps; real frame times are rounded to ms
and forced to increase. The pairs engine uses it as built (one face, no head pose);
``faceclean track`` (trackers/face.py) builds it with ``pose`` (the head's angles) and
``faces``/``choose`` (several faces looked for, one followed).

Rotation (``pose``): MediaPipe's matrix maps its canonical face (right-handed: +X the
subject's left as the camera sees it, +Y up, +Z out of the face) into camera space. Live
Link's frame is that one with X mirrored (faceclean.pose), so its rotation is ``S R S``,
S = diag(-1, 1, 1), read in the Y-X-Z order: yaw = atan2(-R02, R22), pitch = asin(-R12),
roll = atan2(-R10, R11). The matrix's columns are normalised first (it may carry a scale).

The bundle is a zip of TFLite models (``MEMBERS``); ``check_bundle`` refuses, in one line,
one that is not a zip, lacks a model, claims more than ``MAX_MODEL`` unpacked or holds a
model that is not TFLite, before MediaPipe sees it (its own errors are C++ status text).
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52, MEDIAPIPE
from faceclean.errors import FacecleanError
from faceclean.io.source import read_bytes
from faceclean.trackers import quiet
from faceclean.tracking import Reading

NAMES = tuple(n for n in ARKIT52 if n != "tongueOut")  # what the tracker gives, canonical
MAX_MODEL = 64 << 20  # bytes, of the bundle and of its models unpacked (the float16 one: 3.8 MB)
# the models Face Landmarker loads from the bundle (blendshapes: output_face_blendshapes)
MEMBERS = ("face_detector.tflite", "face_landmarks_detector.tflite", "face_blendshapes.tflite")
TFLITE = b"TFL3"  # a TFLite flatbuffer's file identifier, at bytes 4-8
# what zipfile raises on bytes that are no readable zip (RuntimeError: an encrypted member)
_NOT_A_ZIP = (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError, RuntimeError,
              NotImplementedError)  # fmt: skip


# which of several faces to follow: (faces, each (L, 2) landmark px; t s; frame width px)
# -> index into faces
Choose = Callable[[list[np.ndarray], float, int], int]


class Tracker:
    """MediaPipe Face Landmarker, VIDEO mode (faceclean.tracking's interface). ``pose``:
    ask for the facial transformation matrix and give the head's angles (``head_angles``;
    NaN when MediaPipe gives no matrix), else ``Reading.pose`` is None. ``faces``: how many
    MediaPipe looks for; ``choose`` picks the one read (None: MediaPipe's first).
    ``extra``: the install extra a missing mediapipe is told to come with."""

    names = NAMES

    def __init__(
        self,
        model_path: str | os.PathLike,
        threads: int = 1,
        *,
        pose: bool = False,
        faces: int = 1,
        choose: Choose | None = None,
        extra: str = "pairs",
    ) -> None:
        del threads  # MediaPipe's CPU graph picks its own; the job pool spreads the work
        self._landmarker = landmarker(model_path, video=True, blendshapes=True, pose=pose,
                                      extra=extra, faces=faces)  # fmt: skip
        self._pose, self._choose = pose, choose
        self._last_ms = -1
        self._map: tuple[tuple[str, ...], ChannelMap] | None = None

    @property
    def name(self) -> str:
        return version()

    def read(self, frame: np.ndarray, t: float) -> Reading | None:
        """The (51,) scores in ``NAMES`` order, the (478, 3) landmarks (px, as
        ``landmarks``) and, with ``pose``, the (3,) head yaw/pitch/roll (rad) of the face
        followed in an (H, W, 3) uint8 RGB frame, or None (no face)."""
        import mediapipe as mp

        ms = max(int(round(t * 1000.0)), self._last_ms + 1)
        self._last_ms = ms
        image = mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(frame))
        result = self._landmarker.detect_for_video(image, ms)
        if not result.face_blendshapes:
            return None
        k = 0  # which face, of those found
        if self._choose is None:
            points = _pixels(result.face_landmarks[0], frame.shape)
        else:
            found = [_pixels(lm, frame.shape) for lm in result.face_landmarks]
            k = self._choose([f[:, :2] for f in found], t, frame.shape[1])
            points = found[k]
        angles = None
        if self._pose:
            matrices = result.facial_transformation_matrixes
            angles = head_angles(matrices[k]) if len(matrices) > k else np.full(3, np.nan)
        return Reading(self._scores(result.face_blendshapes[k]), points, angles)

    def track(self, frame: np.ndarray, t: float) -> np.ndarray | None:
        """(51,) scores in ``NAMES`` order for an (H, W, 3) uint8 RGB frame, or None (no face)."""
        reading = self.read(frame, t)
        return None if reading is None else reading.scores

    def _scores(self, cats) -> np.ndarray:
        """(51,) in ``NAMES`` order of one face's MediaPipe categories."""
        names = tuple(c.category_name for c in cats)
        if self._map is None or self._map[0] != names:
            self._map = (names, ChannelMap(NAMES, names))
        cmap = self._map[1]
        scores = np.array([c.score for c in cats], np.float64)
        out = np.full(len(NAMES), np.nan)
        out[cmap.have] = scores[cmap.cols]
        return out

    def close(self) -> None:
        self._landmarker.close()

    def __enter__(self) -> Tracker:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def head_angles(matrix: np.ndarray) -> np.ndarray:
    """(3,) Live Link yaw, pitch, roll (rad) of MediaPipe's (4, 4) facial transformation
    (the module docstring's rotation)."""
    r = np.asarray(matrix, np.float64)[:3, :3]
    r = r / np.linalg.norm(r, axis=0, keepdims=True)  # columns: drop any scale
    yaw = np.arctan2(-r[0, 2], r[2, 2])
    pitch = np.arcsin(np.clip(-r[1, 2], -1.0, 1.0))
    roll = np.arctan2(-r[1, 0], r[1, 1])
    return np.array([yaw, pitch, roll])


def version() -> str:
    """MediaPipe's version and model, as a pair's record names the tracker."""
    try:
        from importlib import metadata

        return f"mediapipe {metadata.version('mediapipe')} face_landmarker"
    except Exception:  # pragma: no cover - metadata missing in odd installs
        return "mediapipe face_landmarker"


def landmarker(model_path: str | os.PathLike, video: bool, blendshapes: bool = False,
               pose: bool = False, extra: str = "pairs", faces: int = 1):  # fmt: skip
    """MediaPipe's FaceLandmarker for up to ``faces`` faces from the bundle at ``model_path``
    (read once, bounded, checked by ``check_bundle``): VIDEO mode when ``video``, else
    IMAGE; with the 52 scores (``blendshapes``) and the head's transformation matrix
    (``pose``). A bundle
    MediaPipe refuses, or mediapipe missing (``pip install 'faceclean[EXTRA]'``), is one line."""
    path = Path(model_path)
    bundle = read_bytes(path, MAX_MODEL, "tracker model file")  # regular, bounded, once
    check_bundle(bundle, path)
    quiet()  # MediaPipe's (and the OpenCV it loads) native log lines
    try:
        from mediapipe.tasks.python import BaseOptions
        from mediapipe.tasks.python.vision import (
            FaceLandmarker,
            FaceLandmarkerOptions,
            RunningMode,
        )
    except ImportError:
        raise FacecleanError(f"the tracker needs mediapipe: pip install 'faceclean[{extra}]'"
                             ) from None  # fmt: skip
    options = FaceLandmarkerOptions(
        base_options=BaseOptions(model_asset_buffer=bundle),
        running_mode=RunningMode.VIDEO if video else RunningMode.IMAGE,
        num_faces=faces,
        output_face_blendshapes=blendshapes,
        output_facial_transformation_matrixes=pose,
    )
    try:
        with _native_quiet():
            return FaceLandmarker.create_from_options(options)
    except (RuntimeError, ValueError) as e:
        text = " ".join(str(e).split())[:160]
        raise FacecleanError(f"{path}: not a usable face landmarker model ({text})") from None


@contextlib.contextmanager
def _native_quiet():
    """The process's stderr (fd 2) to /dev/null while MediaPipe builds its graph: its C++
    logs a page of warnings there (absl, TFLite) that no setting turns off and no user can
    act on; a failure still comes back as an exception. FACECLEAN_DEBUG keeps them."""
    if os.environ.get("FACECLEAN_DEBUG"):
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def landmarks(model_path: str | os.PathLike, image: np.ndarray) -> np.ndarray | None:
    """(478, 3) MediaPipe face landmarks of one still RGB ``image`` (H, W, 3) uint8, in
    pixels (x right, y down; z toward the camera negative, in x's pixel scale; 468-477 the
    irises), or None when no face is found. A fresh landmarker in IMAGE mode: no tracking
    state carried from another picture."""
    import mediapipe as mp

    with landmarker(model_path, video=False) as marker:
        img = mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(image))
        result = marker.detect(img)
    if not result.face_landmarks:
        return None
    return _pixels(result.face_landmarks[0], image.shape)


def _pixels(points, shape: tuple[int, ...]) -> np.ndarray:
    """(L, 3) px of MediaPipe's normalised landmarks on an image of ``shape`` (H, W, ...)."""
    h, w = shape[:2]
    return np.array([(p.x * w, p.y * h, p.z * w) for p in points])


def check_bundle(bundle: bytes, path: str | os.PathLike) -> None:
    """Refuse, in one line, bytes that are not a Face Landmarker bundle (see the module)."""
    bad = f"{os.fspath(path)}: not a usable face landmarker model"
    try:
        with zipfile.ZipFile(io.BytesIO(bundle)) as z:
            members = {m.filename: m for m in z.infolist()}
            lacking = [n for n in MEMBERS if n not in members]
            if lacking:
                hint = "give MediaPipe's face_landmarker.task"
                raise FacecleanError(f"{bad} (no {lacking[0]} in the bundle; {hint})")
            unpacked = sum(m.file_size for m in members.values())  # B, as the zip claims
            if unpacked > MAX_MODEL:
                raise FacecleanError(f"{bad} (unpacks to over {MAX_MODEL >> 20} MiB)")
            for n in MEMBERS:
                with z.open(members[n]) as f:
                    if f.read(8)[4:8] != TFLITE:
                        raise FacecleanError(f"{bad} ({n} is not a TFLite model)")
    except _NOT_A_ZIP as e:
        text = " ".join(str(e).split())[:120] or type(e).__name__
        raise FacecleanError(f"{bad} (not a .task bundle: {text})") from None


assert set(NAMES) == set(MEDIAPIPE) - {"_neutral"}
