"""Trackers: frames in, ARKit scores (and the head's rotation) out.

``video`` reads a video file's frames with their own timestamps, or a camera's frames
stamped at capture (a file can stand in for a camera); ``face`` runs MediaPipe Face
Landmarker on them (VIDEO mode) and gives the 51 scores MediaPipe has plus the head's
yaw, pitch and roll from its facial transformation matrix; ``live`` is the camera loop
(track, clean, send); ``signature`` says when a take that claims to be raw MediaPipe
does not look like it. ``face`` and ``video`` need the ``track`` extra (mediapipe, which
brings OpenCV); nothing imports this package at load time but ``faceclean track``.
"""
