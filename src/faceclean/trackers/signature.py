"""Does a take that claims to be raw MediaPipe look like it? One rule, from data.

``--tracker mediapipe`` picks a cleaner fitted on MediaPipe's own output. A tool between
MediaPipe and faceclean may have smoothed, rescaled or remapped the scores (or the take
is no MediaPipe at all); that cleaner then makes it worse, silently. ``judge(values,
names)`` says why a take does not look raw, or None. Three signs, each seen never in
MediaPipe's raw output and each with a wide margin (measured on 85 rendered takes
tracked by MediaPipe 0.10 in VIDEO mode, 73-600 frames each, docs/TRACK.md):

1. **A channel MediaPipe does not move, moving.** MediaPipe gives no ``tongueOut`` and
   keeps ``cheekSquint*``, ``noseSneer*``, ``cheekPuff`` and ``jawForward`` near zero
   (largest seen: 0.008). Any of them above ``SILENT_MAX`` (0.05) is a sign.
2. **Quantised levels.** Raw scores are float32: the smallest step between distinct
   levels of a moving channel is tiny (median over channels at most 0.0004 in any
   take). A median step of ``QUANTUM`` (0.005) or more is a sign (scores rounded to
   two decimals, or to 1/100 as percent).
3. **Rescaled to full range.** At most one channel in a raw take spans [0.01, 0.99];
   ``FULL_RANGE`` (6) or more doing so is a sign of per-channel normalisation.

Signs 2 and 3 need ``MIN_FRAMES`` frames with a face. Smoothing alone is not detected.
``Watch`` wraps a live cleaner: it judges every ``MIN_FRAMES`` frames the stream brings
until one judgement says something, calls ``on_warn(text)`` once, and is silent after.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from faceclean.channels import canonical

SILENT = ("tongueOut", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft",
          "noseSneerRight", "cheekPuff", "jawForward")  # fmt: skip
SILENT_MAX = 0.05  # level; MediaPipe's largest on these: 0.008
QUANTUM = 0.005  # level step; MediaPipe's median smallest step: at most 0.0004
MOVING = 0.1  # a channel whose range exceeds this is moving
FULL_RANGE = 6  # channels spanning [FULL_LO, FULL_HI]; MediaPipe: at most 1
FULL_LO, FULL_HI = 0.01, 0.99
MIN_FRAMES = 60  # face frames before signs 2 and 3 are judged

BLOCK = 4096  # rows judged at once (an hour at 60 fps is 216,001)
SAMPLE = 8192  # rows at most whose levels sign 2 reads (the takes measured: 73-600 frames)


def judge(values: np.ndarray, names: Sequence[str]) -> str | None:
    """Why (N, M) ``values`` over channels ``names`` do not look like raw MediaPipe, in a
    few words, or None when they do (or there is too little to tell)."""
    v = np.asarray(values, np.float64)
    v = v if v.ndim == 2 else v.reshape(0, len(names))
    frames, hi, lo = 0, np.full(v.shape[1], -np.inf), np.full(v.shape[1], np.inf)
    for a in range(0, len(v), BLOCK):  # in blocks: no temporary as large as the take
        part = v[a : a + BLOCK]
        top, low = np.fmax.reduce(part, axis=0), np.fmin.reduce(part, axis=0)  # NaN skipped
        if np.isinf(top).any() or np.isinf(low).any():  # an infinite reading: not a level
            finite = np.isfinite(part)
            part = np.where(finite, part, np.nan)
            top, low = np.fmax.reduce(part, axis=0), np.fmin.reduce(part, axis=0)
        frames += len(part) - int(np.isnan(np.fmax.reduce(part, axis=1)).sum())  # a face
        hi, lo = np.fmax(hi, top), np.fmin(lo, low)
    if not frames:
        return None
    canon = [canonical(str(n)) for n in names]
    moving = [canon[j] for j in range(len(canon)) if canon[j] in SILENT and hi[j] > SILENT_MAX]
    if moving:
        j = canon.index(moving[0])
        more = f" (and {len(moving) - 1} more)" if len(moving) > 1 else ""
        return f"{moving[0]} reaches {hi[j]:.2f}{more}, a channel MediaPipe keeps near 0"
    if frames < MIN_FRAMES:
        return None
    full = int(np.sum((lo <= FULL_LO) & (hi >= FULL_HI)))
    if full >= FULL_RANGE:
        return f"{full} channels span the whole 0-1 range, as per-channel rescaling makes"
    steps = []
    sample = v[:: -(-len(v) // SAMPLE)]  # rows spread over the take: an hour's sort is 0.3 s
    for j in np.flatnonzero(hi - lo > MOVING):
        levels = np.unique(sample[np.isfinite(sample[:, j]), j])
        if len(levels) > 1:
            steps.append(float(np.min(np.diff(levels))))
    if steps and np.median(steps) >= QUANTUM:
        return f"levels come in steps of {np.median(steps):.3g} (quantised)"
    return None


def warning(why: str, what: str) -> str:
    """The one line said when ``what`` (a file, a stream) does not look raw."""
    return (
        f"faceclean: warning: {what} does not look like raw MediaPipe output ({why}); the "
        "--tracker mediapipe cleaner is fitted on raw scores and may make this take worse: "
        "give the tracker's raw output, or choose a cleaner with --method"
    )


class Watch:
    """A stream cleaner that also watches its input for ``judge``'s signs (see the
    module docstring); steps and resets as ``inner`` does."""

    def __init__(self, inner, names: Sequence[str], on_warn: Callable[[str], None]) -> None:
        self.inner = inner
        self.names = tuple(names)
        self.on_warn = on_warn
        self.warned = False
        self._rows: list[np.ndarray] = []

    def __getattr__(self, name: str):
        return getattr(self.inner, name)

    def reset(self) -> None:
        self._rows = []  # a new stream (or a warm-up's end) is judged on its own
        self.inner.reset()

    def steps(self, times: np.ndarray, values: np.ndarray) -> np.ndarray:
        """A block (B, M) as ``step`` would take it frame by frame: judged MIN_FRAMES
        rows at a time, then the inner cleaner's own ``steps`` (its compiled loop)."""
        rows = np.asarray(values, np.float64)
        rows = rows[np.isfinite(rows).any(axis=1)]
        while not self.warned and len(rows):
            need = MIN_FRAMES - len(self._rows)
            self._take(rows[:need])
            rows = rows[need:]
        return self.inner.steps(times, values)

    def step(self, frame: np.ndarray, t: float) -> np.ndarray:
        if not self.warned:
            x = np.asarray(frame, np.float64)
            if np.isfinite(x).any():
                self._take(x[None])
        return self.inner.step(frame, t)

    def _take(self, rows: np.ndarray) -> None:
        """Keeps ``rows`` (n, M) face frames; once MIN_FRAMES are kept, judges them (and
        warns, once) and starts again."""
        self._rows.extend(rows.copy())
        if len(self._rows) >= MIN_FRAMES:
            why = judge(np.array(self._rows), self.names)
            self._rows = []
            if why is not None:
                self.warned = True
                self.on_warn(why)
