"""Record a relay session as two takes: what came in, and what went out cleaned.

``Recorder(path)`` keeps every frame the relay cleaned: its time, the input as received
and the cleaned output (ARKit-52 order; channels the sender lacks are left out), and the
Live Link head and eye angles when the stream carries them. ``save()`` writes the input
to ``path`` and the output beside it as ``<stem>.clean<ext>`` (Live Link CSV for
``.csv``, NPZ for ``.npz``), atomically, so a session becomes a take that ``faceclean
replay`` streams again and ``faceclean clean`` re-cleans.

Times start at 0 on the first frame and are those the cleaner saw. A new stream (the
relay restarted its cleaner: the sender restarted or changed its time base) goes on
``GAP`` s after the last recorded frame, longer than any cleaner's ``max_gap``, so
cleaning the recording restarts there too. A frame without a single finite value
(tracking loss) is a missing row of the input; the output keeps what was sent for it
(the held last frame). Memory: about 0.7 KB per frame (150 MB an
hour at 60 fps).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.io.atomic import check_writable
from faceclean.relay.frame import POSE_NAMES

GAP = 1.0  # s between two streams in one recording
FORMATS = {".csv": "livelink", ".npz": "npz"}


def clean_path(path: str | os.PathLike) -> Path:
    """Where the cleaned output of a recording at ``path`` goes: ``take.clean.csv``."""
    p = Path(path)
    return p.with_name(f"{p.stem}.clean{p.suffix}")


class Recorder:
    """Frames in, cleaned frames out; ``save()`` writes both (see the module docstring)."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.fmt = FORMATS.get(self.path.suffix.lower())
        if self.fmt is None:
            raise FacecleanError(
                f"--record {self.path.name}: give a .csv (Live Link) or .npz file name"
            )
        try:  # now, not when the session ends: the -o policy for both files
            check_writable(self.path, clean_path(self.path))
        except FacecleanError as e:
            raise FacecleanError(f"--record: {e}") from None
        self._t: list[float] = []
        self._x: list[np.ndarray] = []  # (52,) float64 each
        self._y: list[np.ndarray] = []  # (52,) float32 each
        self._pose: list[np.ndarray] = []  # (9,) each
        self._seen = np.zeros(len(ARKIT52), bool)
        self._has_pose = False
        self._shift = 0.0  # s added to the stream's times
        self._t0: float | None = None
        self._new_stream = False

    def __len__(self) -> int:
        return len(self._t)

    def restart(self) -> None:
        """The next frame starts a new stream (the relay reset its cleaner)."""
        self._new_stream = True

    def add(self, t: float, x: np.ndarray, y: np.ndarray, pose: np.ndarray | None) -> None:
        """One cleaned frame: t s, input x and output y (52,) (NaN: absent), pose (9,)."""
        if self._t0 is None:
            self._t0 = t
        elif self._new_stream:
            self._shift = self._t[-1] + GAP - (t - self._t0)
        self._new_stream = False
        self._t.append(t - self._t0 + self._shift)
        self._x.append(np.array(x, np.float64))  # exact: what the cleaner saw
        self._y.append(np.asarray(y, np.float32))
        self._seen |= np.isfinite(x)
        if pose is not None:
            self._has_pose = True
        self._pose.append(np.zeros(len(POSE_NAMES)) if pose is None else np.asarray(pose))

    def animations(self) -> tuple[Animation, Animation]:
        """(input, cleaned output) over the channels the stream carried."""
        if not self._t:
            raise FacecleanError("nothing to record: no face frame was relayed")
        cols = np.flatnonzero(self._seen) if self._seen.any() else np.arange(len(ARKIT52))
        names = tuple(ARKIT52[j] for j in cols)
        times = np.asarray(self._t)
        meta = {}
        if self._has_pose:
            meta = {"pose": np.asarray(self._pose), "pose_names": POSE_NAMES}
        x = np.asarray(self._x)[:, cols]
        x[~np.isfinite(x).any(axis=1)] = np.nan  # a frame without one value: missing
        y = np.asarray(self._y, np.float64)[:, cols]
        return Animation(times, x, names, dict(meta)), Animation(times, y, names, dict(meta))

    def save(self) -> tuple[Path, Path]:
        """Write the input and the cleaned output; their paths."""
        from faceclean import io

        take, cleaned = self.animations()
        io.save(take, self.path, fmt=self.fmt)
        io.save(cleaned, clean_path(self.path), fmt=self.fmt)
        return self.path, clean_path(self.path)
