"""A still *real* face, tracked live: does a cleaner invent motion where there is none?

scikit-image's ``astronaut`` photograph (public domain, shipped inside scikit-image) is shown
to MediaPipe as a video: each frame shifted by a sub-pixel random walk (a hand-held phone,
at most ``MAX_SHIFT`` px) and given fresh sensor noise, at 30 fps. The face does not move
at all, so every change of the scores is the tracker's. Measures, over the frames after a
1 s warm-up:

- change: mean |y[n] - y[n-1]| over channels and frames, cleaned over raw (1.0: none removed);
- drift: max over channels of |mean of the last second - mean of the first second| (a
  level that wanders; 0 ideal).
"""

from __future__ import annotations

import numpy as np

from faceclean.animation import Animation
from faceclean.errors import FacecleanError

MAX_SHIFT = 1.5  # px
NOISE = 3.0  # sensor noise sigma, 0..255 units
WARM = 1.0  # s


def still_take(model_path, seconds: float = 10.0, fps: float = 30.0, seed: int = 0) -> Animation:
    """MediaPipe's scores for the still photograph (module docstring) as a take."""
    from scipy.ndimage import shift

    try:
        from skimage import data
    except ImportError:
        raise FacecleanError(
            "the still-face test needs scikit-image (pip install scikit-image)"
        ) from None
    from faceclean.synthetic.render import jpeg
    from faceclean.trackers.mediapipe import NAMES, Tracker

    image = data.astronaut().astype(np.float32)  # (512, 512, 3)
    rng = np.random.default_rng(seed)
    n = int(seconds * fps)
    times = np.arange(n) / fps
    offset = np.zeros(2)
    out = np.full((n, len(NAMES)), np.nan)
    with Tracker(model_path) as tracker:
        for k, t in enumerate(times):
            offset = np.clip(offset + rng.normal(0, 0.15, 2), -MAX_SHIFT, MAX_SHIFT)
            frame = shift(image, (offset[0], offset[1], 0), order=1, mode="nearest")
            frame += rng.normal(0, NOISE, frame.shape).astype(np.float32)
            frame = jpeg(np.clip(frame + 0.5, 0, 255).astype(np.uint8), 90)
            y = tracker.track(frame, float(t))
            if y is not None:
                out[k] = y
    if np.isnan(out).all():
        raise FacecleanError("MediaPipe found no face in the still photograph")
    return Animation(times, out, NAMES, {"format": "csv"})


def measures(take: Animation) -> dict[str, float]:
    """{"change": mean |dy| per frame, "drift": max |last-second mean - first-second mean|}."""
    t, y = take.times, take.values
    keep = (t >= t[0] + WARM) & take.valid
    t, y = t[keep], y[keep]
    change = float(np.nanmean(np.abs(np.diff(y, axis=0))))
    first, last = y[t < t[0] + 1.0], y[t > t[-1] - 1.0]
    drift = float(np.nanmax(np.abs(np.nanmean(last, 0) - np.nanmean(first, 0))))
    return {"change": change, "drift": drift}
