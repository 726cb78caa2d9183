"""Rendered faces and a real tracker in the loop: (tracked, truth) pairs from known weights.

``head`` (the ICT head and its painted regions), ``scene`` (a take's randomised factors,
drawn from a seed and a render setting), ``raster`` + ``render`` (frames), ``tracker``
(MediaPipe Face Landmarker), ``pairs`` (the data job). Needs the ``pairs`` extra
(numba, mediapipe); nothing else in faceclean imports this package at load time.
"""
