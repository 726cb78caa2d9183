"""Frames and their times: a video file's own timestamps, or a camera's capture clock.

``Video(path)`` reads a file through OpenCV (its FFmpeg backend) and yields ``(rgb, t)``:
(H, W, 3) uint8 RGB and the frame's presentation time in seconds
(``CAP_PROP_POS_MSEC`` after each read), so a variable-frame-rate video keeps its real
times. Rule for a time that is not after the previous one (a container without
timestamps): it becomes the previous time plus one nominal frame (1 / the container's
fps, 1/30 s when it states none). A file that is not a video, or that stops well before
the frame count its container states (truncated mid-stream), is refused in one line.

``Camera(source)`` is a live source: an OpenCV camera index, or a video file standing in
for one (played at its own pace, so a test feeds the live path as a camera would). A
capture thread reads frames as they come and stamps each with ``time.monotonic()`` at
capture; the consumer takes only the newest (``latest``), and a frame replaced before it
was taken is counted in ``dropped``, as the relay counts stale frames. A source that
stops delivering ends the camera with ``lost`` saying why: a camera whose read fails
(unplugged, or its driver gave up), a stand-in file that fails mid-stream (truncated), or
no frame for ``stall`` seconds (``FIRST_FRAME`` s for the first: a webcam takes a moment
to start). A stand-in file's end is a normal end (``lost`` None).
"""

from __future__ import annotations

import os
import stat
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from faceclean.errors import FacecleanError
from faceclean.trackers import quiet

NOMINAL_FPS = 30.0  # Hz, when a container states no rate
TRUNCATED = 0.9  # a file that yields under this share of its stated frame count is truncated
STALL = 2.0  # s without a new frame: the camera has stopped delivering
FIRST_FRAME = 10.0  # s allowed for a camera's first frame


def _cv2():
    quiet()
    try:
        import cv2
    except ImportError:
        raise FacecleanError("reading video needs OpenCV: pip install 'faceclean[track]'") from None
    return cv2


def check_video_file(path: str | os.PathLike) -> os.stat_result:
    """The ``stat`` of a readable regular file at ``path``, or one line saying why not."""
    from faceclean.io import paths

    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise FacecleanError(f"{p}: no such file") from None
    except OSError as e:
        raise FacecleanError(f"{p}: {e.strerror or e}") from None
    if not stat.S_ISREG(st.st_mode) or paths.kernel(p, st):
        raise FacecleanError(f"{p}: not a regular file (a video file is)")
    if not os.access(p, os.R_OK):
        raise FacecleanError(f"{p}: not readable")
    paths.note_input(st)  # an output naming this video is refused
    return st


class Video:
    """A video file's frames, each with its own time (see the module docstring)."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        check_video_file(self.path)
        cv2 = _cv2()
        self._cap = cv2.VideoCapture(str(self.path), cv2.CAP_FFMPEG)
        if not self._cap.isOpened():
            raise FacecleanError(f"{self.path}: not a video OpenCV can read")
        self.fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)  # Hz, as the container says
        self.frame_count = max(int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0), 0)
        self.read = 0  # frames read so far

    def __iter__(self) -> Iterator[tuple[np.ndarray, float]]:
        cv2 = _cv2()
        step = 1.0 / (self.fps if 0 < self.fps < 1000 else NOMINAL_FPS)  # s
        last: float | None = None
        while True:
            ok, bgr = self._cap.read()
            if not ok or bgr is None:
                break
            t = float(self._cap.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0  # s
            if not np.isfinite(t) or (last is not None and t <= last):
                t = 0.0 if last is None else last + step
            last = t
            self.read += 1
            yield cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), t
        if self.read == 0:
            raise FacecleanError(f"{self.path}: not a video (no frame could be decoded)")
        if self.frame_count and self.read < TRUNCATED * self.frame_count:
            raise FacecleanError(
                f"{self.path}: truncated: {self.read} of the {self.frame_count} frames its "
                "container states could be decoded"
            )

    def close(self) -> None:
        self._cap.release()

    def __enter__(self) -> Video:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Camera:
    """A live source: ``Camera(0)`` (an OpenCV camera index) or ``Camera("take.mp4")`` (a
    file played at its own pace, standing in for a camera). ``start()``, then ``latest()``
    gives the newest ``(rgb, t)`` not yet taken, t in ``time.monotonic()`` seconds at
    capture (see the module docstring). ``stall``: s without a frame that end it as lost."""

    def __init__(self, source: int | str | os.PathLike, stall: float = STALL) -> None:
        self.source = source
        self.stall = stall
        self.captured = 0  # frames read from the source
        self.dropped = 0  # frames replaced by a newer one before they were taken
        self.ended = False  # the source stopped delivering (a file's end, an unplugged camera)
        self.lost: str | None = None  # why it stopped, when that was not a file's normal end
        self._last = time.monotonic()  # s, when the last frame came (or the capture started)
        self._slot: tuple[np.ndarray, float] | None = None
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._video: Video | None = None
        self._cap = None
        if isinstance(source, int):
            cv2 = _cv2()
            self._cap = cv2.VideoCapture(source)
            if not self._cap.isOpened():
                self._cap.release()
                raise FacecleanError(f"camera {source} does not open (no such camera, or busy)")
        else:
            self._video = Video(source)

    def start(self) -> Camera:
        self._last = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="camera", daemon=True)
        self._thread.start()
        return self

    def latest(self, timeout: float = 1.0) -> tuple[np.ndarray, float] | None:
        """The newest frame not yet taken, waiting up to ``timeout`` s; None if none came.
        No frame for ``stall`` s (``FIRST_FRAME`` before the first) ends the camera as lost."""
        with self._cond:
            if self._slot is None and not self.ended:
                self._cond.wait(timeout)
            frame, self._slot = self._slot, None
            if frame is None and not self.ended:
                limit = self.stall if self.captured else max(self.stall, FIRST_FRAME)
                if time.monotonic() - self._last > limit:
                    self._end(f"no frame for {limit:g} s")
        return frame

    def _end(self, lost: str | None) -> None:
        """Mark the source ended (``lost``: why, when it failed); hold ``_cond``."""
        if not self.ended:
            self.ended, self.lost = True, lost
            self._stop.set()
            self._cond.notify_all()

    def _put(self, rgb: np.ndarray) -> None:
        t = time.monotonic()  # s, stamped at capture
        with self._cond:
            if self._slot is not None:
                self.dropped += 1
            self._slot = (rgb, t)
            self._last = t
            self.captured += 1
            self._cond.notify()

    def _run(self) -> None:
        lost: str | None = "the capture stopped"  # unless it returns why, or a file's end
        try:
            lost = self._play() if self._video is not None else self._grab()
        finally:
            with self._cond:
                self._end(lost)

    def _play(self) -> str | None:
        """Play the stand-in file at its own pace; None at its end, else why it failed."""
        start: float | None = None
        try:
            for rgb, t in self._video:
                if start is None:
                    start = time.monotonic() - t
                wait = start + t - time.monotonic()
                if wait > 0 and self._stop.wait(wait):
                    return None
                if self._stop.is_set():
                    return None
                self._put(rgb)
        except FacecleanError as e:  # a truncated stand-in ends as an unplugged camera would
            return f"the file failed mid-stream: {e}"
        return None

    def _grab(self) -> str | None:
        """Read the camera until stopped (None) or until a read fails (why)."""
        cv2 = _cv2()
        while not self._stop.is_set():
            ok, bgr = self._cap.read()
            if not ok or bgr is None:
                return "a read failed (unplugged, or its driver gave up)"
            self._put(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        return None

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._video is not None:
            self._video.close()
        if self._cap is not None:
            self._cap.release()

    def __enter__(self) -> Camera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
