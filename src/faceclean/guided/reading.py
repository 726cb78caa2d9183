"""What each tracker can show: the ARKit channels its readings never move.

A prompt aimed only at channels the tracker does not read cannot be seen in its take
however well the person performs it, so the alignment places it by timing (guided/align.py)
instead of counting it as not performed. The list is measured, per tracker, by
``survey``: over (tracked, truth) pairs, the frames where a channel's true weight is at
least ``TRUE_MIN``, and there the ``Q``-th percentile of the tracker's raw score; a channel
whose percentile stays under ``READ_MIN`` is not read.

MediaPipe (face landmarker, VIDEO mode), on the pairs the shipped MediaPipe map is fitted
on (``~/.cache/faceclean/families``, and ``families-gaze``, the same with turning eyes: 343
rendered takes, painted, dressed and photo faces in every setting)::

    channel              frames >= 0.5   raw score there, 90th percentile
    cheekSquintLeft/Right    9,357/9,214  0.000
    noseSneerLeft/Right     10,303/9,392  0.000
    cheekPuff                8,987        0.001
    jawForward               7,371        0.002
    mouthFrownLeft/Right   10,753/10,136  0.008/0.006
    jawRight                 9,023        0.010
    mouthClose               8,191        0.026
    jawLeft                  9,956        0.027
    tongueOut                    -        (MediaPipe gives none)

Every other channel reads at least 0.055 there (mouthRollUpper; eyeWide 0.085/0.137; most
0.3-0.95). ARKit reads every channel.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52

TRUE_MIN = 0.5  # weight: the face moved the channel at least half way
Q = 90.0  # percentile of the raw score over those frames
READ_MIN = 0.05  # weight: under this the tracker does not read the channel
MIN_FRAMES = 100  # frames over TRUE_MIN a channel needs to be judged
LABELS = {"arkit": "ARKit", "mediapipe": "MediaPipe"}

UNREAD: dict[str, tuple[str, ...]] = {
    "arkit": (),
    "mediapipe": (
        "jawForward", "jawLeft", "jawRight", "mouthClose", "mouthFrownLeft",
        "mouthFrownRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight",
        "noseSneerLeft", "noseSneerRight", "tongueOut",
    ),
}  # fmt: skip


def unread(tracker: str) -> frozenset[str]:
    """The ARKit channels ``tracker`` does not read (none for a tracker not measured)."""
    return frozenset(UNREAD.get(tracker, ()))


def label(tracker: str) -> str:
    return LABELS.get(tracker, tracker)


def survey(pairs: Iterable[tuple[Animation, Animation]]) -> dict[str, tuple[int, float]]:
    """{ARKit name: (frames with truth >= TRUE_MIN, the Q-th percentile of the tracker's
    raw score there)} over (tracked, truth) pairs at the same instants; a channel the
    tracker lacks, or no frame reaches, is left out."""
    scores: dict[str, list[np.ndarray]] = {n: [] for n in ARKIT52}
    for tracked, truth in pairs:
        x, have = tracked.arkit()  # (N, 52), NaN rows: no face
        w, known = truth.arkit()
        n = min(len(x), len(w))
        for j, name in enumerate(ARKIT52):
            if have[j] and known[j]:
                rows = np.isfinite(x[:n, j]) & (np.nan_to_num(w[:n, j]) >= TRUE_MIN)
                scores[name].append(x[:n][rows, j])
    out = {}
    for name, parts in scores.items():
        got = np.concatenate(parts) if parts else np.zeros(0)
        if got.size:
            out[name] = (int(got.size), float(np.percentile(got, Q)))
    return out


def not_read(found: dict[str, tuple[int, float]]) -> tuple[str, ...]:
    """The channels of a ``survey`` the tracker does not read (enough frames, under READ_MIN)."""
    return tuple(n for n, (k, q) in found.items() if k >= MIN_FRAMES and q < READ_MIN)
