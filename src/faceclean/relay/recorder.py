"""Record a relay session as two takes: what came in, and what went out cleaned.

``Recorder(path)`` keeps every frame the relay cleaned: its time, the input as received
and the cleaned output (ARKit-52 order; channels the sender lacks are left out), and the
Live Link head and eye angles when the stream carries them. ``save()`` writes the input
to ``path`` and the output beside it as ``<stem>.clean<ext>`` (Live Link CSV for
``.csv``, NPZ for ``.npz``), atomically, so a session becomes a take that ``faceclean
replay`` streams again and ``faceclean clean`` re-cleans.

Times start at 0 on the first frame and are those the cleaner saw; the head and eye
angles are the received ones in the input and the cleaned ones in the output.

Timecode: a stream that carries one (Live Link: frame number, sub-frame, rate) is
recorded on it: ``timecode_start`` is the first frame's timecode (seconds of the day,
written as the Live Link CSV's ``Timecode``) and times follow the tracker's, so the file
carries the tracker's own timecode. A stream without one (VMC, iFacialMocap) is recorded
on its arrival time: ``timecode_start`` is the local time of day when the first frame
arrived, and every frame's arrival time (s of the day) is kept in an ``ArrivalTime``
column (``ARRIVAL``), which is how the file says its timecode is an arrival time
(``faceclean info`` reads it so).

A new stream (the relay restarted its cleaner: the sender restarted or changed its time
base) goes on ``GAP`` s after the last recorded frame (a timecoded stream that resumes
later than that keeps its own timecode), longer than any cleaner's ``max_gap``, so
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
from faceclean.relay.frame import POSE_NAMES, Timecode

GAP = 1.0  # s between two streams in one recording
DAY = 86400.0  # s
ARRIVAL = "ArrivalTime"  # the column of arrival times (s of the day) of an untimed stream
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
        self.check()
        self._t: list[float] = []
        self._x: list[np.ndarray] = []  # (52,) float64 each
        self._y: list[np.ndarray] = []  # (52,) float32 each
        self._pose: list[np.ndarray] = []  # (9,) each, as received
        self._pose_out: list[np.ndarray] = []  # (9,) each, cleaned
        self._arrival: list[float] = []  # s of the local day
        self._start: float | None = None  # s of the day of the first frame
        self._timed = False  # the stream carries its own timecode
        self._seen = np.zeros(len(ARKIT52), bool)
        self._has_pose = False
        self._shift = 0.0  # s added to the stream's times
        self._t0: float | None = None
        self._new_stream = False

    def check(self) -> None:
        """The -o policy for both files, now, not when the session ends; again once the
        command has read its inputs (a --record naming its --calibration was refused only
        at the end, the session lost)."""
        try:
            check_writable(self.path, clean_path(self.path))
        except FacecleanError as e:
            raise FacecleanError(f"--record: {e}") from None

    def __len__(self) -> int:
        return len(self._t)

    def restart(self) -> None:
        """The next frame starts a new stream (the relay reset its cleaner)."""
        self._new_stream = True

    def add(
        self,
        t: float,
        x: np.ndarray,
        y: np.ndarray,
        pose: np.ndarray | None,
        pose_out: np.ndarray | None = None,
        timecode: Timecode | None = None,
        arrival: float | None = None,
    ) -> None:
        """One cleaned frame: t s, input x and output y (52,) (NaN: absent), the pose (9,)
        received and cleaned (None: the same), the sender's timecode, the arrival time
        (s since the epoch; None: now)."""
        import time as clock

        now = clock.time() if arrival is None else arrival
        local = clock.localtime(now)
        arrived = local.tm_hour * 3600 + local.tm_min * 60 + local.tm_sec + now % 1.0
        if self._t0 is None:
            self._t0 = t
            self._timed = timecode is not None
            if timecode is not None:  # the tracker's timecode: t is its time in s
                number, sub, num, den = timecode
                self._start = ((number + sub) * den / num) % DAY
            else:
                self._start = arrived
        elif self._new_stream:
            ahead = t - self._t0 + self._shift > self._t[-1] + GAP
            if not (self._timed and ahead):
                self._shift = self._t[-1] + GAP - (t - self._t0)
        self._new_stream = False
        self._arrival.append(arrived)
        self._t.append(t - self._t0 + self._shift)
        self._x.append(np.array(x, np.float64))  # exact: what the cleaner saw
        self._y.append(np.asarray(y, np.float32))
        self._seen |= np.isfinite(x)
        if pose is not None:
            self._has_pose = True
        zeros = np.zeros(len(POSE_NAMES))
        self._pose.append(zeros if pose is None else np.nan_to_num(np.asarray(pose)))
        out = pose if pose_out is None else pose_out
        self._pose_out.append(zeros if out is None else np.nan_to_num(np.asarray(out)))

    def animations(self) -> tuple[Animation, Animation]:
        """(input, cleaned output) over the channels the stream carried."""
        if not self._t:
            raise FacecleanError("nothing to record: no face frame was relayed")
        cols = np.flatnonzero(self._seen) if self._seen.any() else np.arange(len(ARKIT52))
        names = tuple(ARKIT52[j] for j in cols)
        times = np.asarray(self._t)
        extra = [] if self._timed else [np.asarray(self._arrival)[:, None]]  # (N, 1)
        extra_names = () if self._timed else (ARRIVAL,)
        meta: dict = {"timecode_start": float(self._start or 0.0)}
        pose_in = pose_out = np.zeros((len(times), 0))
        if self._has_pose:
            pose_in, pose_out = np.asarray(self._pose), np.asarray(self._pose_out)
        names_p = (POSE_NAMES if self._has_pose else ()) + extra_names
        x = np.asarray(self._x)[:, cols]
        x[~np.isfinite(x).any(axis=1)] = np.nan  # a frame without one value: missing
        y = np.asarray(self._y, np.float64)[:, cols]
        takes = []
        for values, pose in ((x, pose_in), (y, pose_out)):
            m = dict(meta)
            if names_p:
                m.update(pose=np.hstack([pose, *extra]), pose_names=names_p)
            takes.append(Animation(times, values, names, m))
        return takes[0], takes[1]

    def there(self) -> list[Path]:
        """The files ``save`` would write over (said, never replaced in silence)."""
        return [p for p in (self.path, clean_path(self.path)) if p.is_file()]

    def save(self) -> tuple[Path, Path]:
        """Write the input and the cleaned output; their paths."""
        from faceclean import io
        from faceclean.io.atomic import together

        take, cleaned = self.animations()
        with together():  # both written, then both renamed: never one new beside one old
            io.save(take, self.path, fmt=self.fmt)
            io.save(cleaned, clean_path(self.path), fmt=self.fmt)
        return self.path, clean_path(self.path)
