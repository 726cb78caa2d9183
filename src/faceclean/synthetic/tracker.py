"""The tracker in the loop: Google's MediaPipe Face Landmarker, in VIDEO mode.

``Tracker(model_path)`` loads the ``face_landmarker.task`` bundle from a file (never
downloaded: ``settings.tracker_model()``, ``../shared/models`` by default). It is a
faceclean.tracking ``Tracker``: ``read(frame, t)`` gives the 51 ARKit scores of one RGB
frame at ``t`` seconds, in MediaPipe's names mapped onto canonical ARKit (``_neutral``
dropped; MediaPipe has no ``tongueOut``), with the 478 landmarks (no head pose: it does not
ask MediaPipe for the matrix), or None when no face is found: a lost face is a missing
frame. ``track(frame, t)`` gives the scores alone. VIDEO mode needs increasing integer
millisecond timestamps; real frame times are rounded to ms and forced to increase.

The bundle is a zip of TFLite models (``MEMBERS``); ``check_bundle`` refuses, in one line,
one that is not a zip, lacks a model, claims more than ``MAX_MODEL`` unpacked or holds a
model that is not TFLite, before MediaPipe sees it (its own errors are C++ status text).
"""

from __future__ import annotations

import io
import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52, MEDIAPIPE
from faceclean.errors import FacecleanError
from faceclean.io.source import read_bytes
from faceclean.tracking import Reading

NAMES = tuple(n for n in ARKIT52 if n != "tongueOut")  # what the tracker gives, canonical
MAX_MODEL = 64 << 20  # bytes, of the bundle and of its models unpacked (the float16 one: 3.8 MB)
# the models Face Landmarker loads from the bundle (blendshapes: output_face_blendshapes)
MEMBERS = ("face_detector.tflite", "face_landmarks_detector.tflite", "face_blendshapes.tflite")
TFLITE = b"TFL3"  # a TFLite flatbuffer's file identifier, at bytes 4-8
# what zipfile raises on bytes that are no readable zip (RuntimeError: an encrypted member)
_NOT_A_ZIP = (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError, RuntimeError,
              NotImplementedError)  # fmt: skip


class Tracker:
    """MediaPipe Face Landmarker, VIDEO mode, one face (faceclean.tracking's interface)."""

    names = NAMES

    def __init__(self, model_path: str | os.PathLike, threads: int = 1) -> None:
        del threads  # MediaPipe's CPU graph picks its own; the job pool spreads the work
        self._landmarker = landmarker(model_path, video=True, blendshapes=True)
        self._last_ms = -1
        self._map: tuple[tuple[str, ...], ChannelMap] | None = None

    @property
    def name(self) -> str:
        return version()

    def read(self, frame: np.ndarray, t: float) -> Reading | None:
        """The (51,) scores in ``NAMES`` order and the (478, 3) landmarks (px, as
        ``landmarks``) of an (H, W, 3) uint8 RGB frame, or None (no face)."""
        result = self._detect(frame, t)
        if result is None:
            return None
        return Reading(self._scores(result), _pixels(result.face_landmarks[0], frame.shape))

    def track(self, frame: np.ndarray, t: float) -> np.ndarray | None:
        """(51,) scores in ``NAMES`` order for an (H, W, 3) uint8 RGB frame, or None (no face)."""
        result = self._detect(frame, t)
        return None if result is None else self._scores(result)

    def _detect(self, frame: np.ndarray, t: float):
        """MediaPipe's result for the frame, or None (no face)."""
        import mediapipe as mp

        ms = max(int(round(t * 1000.0)), self._last_ms + 1)
        self._last_ms = ms
        image = mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(frame))
        result = self._landmarker.detect_for_video(image, ms)
        return result if result.face_blendshapes else None

    def _scores(self, result) -> np.ndarray:
        cats = result.face_blendshapes[0]
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
    os.environ.setdefault("GLOG_minloglevel", "2")  # MediaPipe's C++ log lines
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
        return FaceLandmarker.create_from_options(options)
    except (RuntimeError, ValueError) as e:
        text = " ".join(str(e).split())[:160]
        raise FacecleanError(f"{path}: not a usable face landmarker model ({text})") from None


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
