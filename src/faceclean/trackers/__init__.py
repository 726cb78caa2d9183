"""Trackers: frames in, ARKit scores (and the head's rotation) out.

``video`` reads a video file's frames with their own timestamps, or a camera's frames
stamped at capture (a file can stand in for a camera); ``face`` runs MediaPipe Face
Landmarker on them (VIDEO mode) and gives the 51 scores MediaPipe has plus the head's
yaw, pitch and roll from its facial transformation matrix; ``live`` is the camera loop
(track, clean, send); ``signature`` says when a take that claims to be raw MediaPipe
does not look like it. ``face`` and ``video`` need the ``track`` extra (mediapipe, which
brings OpenCV); nothing imports this package at load time but ``faceclean track``.
"""

import os


def quiet() -> None:
    """Before OpenCV or MediaPipe loads: their native log lines (a bad file's ffmpeg
    errors, a missing camera's backends, MediaPipe's C++ warnings) stay off stderr, where
    faceclean's one line says what went wrong. FACECLEAN_DEBUG keeps them."""
    if os.environ.get("FACECLEAN_DEBUG"):
        return
    os.environ.setdefault("OPENCV_LOG_LEVEL", "SILENT")
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
    os.environ.setdefault("GLOG_minloglevel", "2")
