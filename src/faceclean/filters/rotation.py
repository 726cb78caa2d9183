"""The rotation filter: One Euro on angles, on the circle (head and eye yaw/pitch/roll).

Per angle, radians, with wrap(a) the angle a brought into (-pi, pi]:

    d   = wrap(x - y_prev)                     # the short way round, rad
    edx = edx_prev + alpha(d_cutoff) (d / dt - edx_prev)      # rad/s
    fc  = min_cutoff + beta |edx|              # Hz
    y   = x - (1 - alpha(fc)) d                # y_prev + alpha d, on x's side of the cut

So a head that turns through +-pi (yaw 3.13 -> -3.13 rad) moves 0.02 rad, not 6.26, and
the output stays on the input's branch: an angle away from the cut comes out as plain One
Euro would give it. Cut-offs in Hz, beta in Hz per rad/s; the step contract and the time
rules (tracking loss, gaps, repeated times) are filters/base.py's. Settings per group
(``head``, ``eyes``: faceclean.channels.POSE_GROUPS) come from the shipped tuned preset
``presets/rotation.json`` (benchmarks/tune_rotation.py) and ``--set head.min_cutoff=0.5``.
"""

from __future__ import annotations

from collections.abc import Sequence
from fnmatch import fnmatchcase

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import POSE, POSE_GROUPS, pose_name
from faceclean.filters.base import State, StreamCleaner
from faceclean.filters.one_euro import DT_MIN, alpha
from faceclean.filters.params import per_channel


def wrap(a: np.ndarray) -> np.ndarray:
    """Angles (rad, any shape) brought into (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


class Rotation(StreamCleaner):
    """One Euro on the circle: ``min_cutoff`` Hz, ``beta`` Hz/(rad/s), ``d_cutoff`` Hz."""

    name = "rotation"
    PER_CHANNEL = ("min_cutoff", "beta", "d_cutoff")

    def __init__(
        self,
        *,
        min_cutoff: float | Sequence[float] = 1.5,  # One Euro's defaults; the shipped
        beta: float | Sequence[float] = 3.0,  # preset (tuned) is what resolve builds
        d_cutoff: float | Sequence[float] = 1.0,
        names: Sequence[str] = POSE,
    ) -> None:
        self.names = tuple(names)
        self.min_cutoff = per_channel(min_cutoff, names, "rotation min_cutoff")
        self.beta = per_channel(beta, names, "rotation beta", open_low=False)
        self.d_cutoff = per_channel(d_cutoff, names, "rotation d_cutoff")
        self.reset()

    def _start(self, x: np.ndarray) -> State:
        return x.copy(), np.zeros_like(x)

    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        y, edx = state  # (S, M) rad, (S, M) rad/s
        dt = np.maximum(dt, DT_MIN)  # (S, 1) s
        d = wrap(x - y)
        edx = edx + alpha(self.d_cutoff, dt) * (d / dt - edx)
        cutoff = self.min_cutoff + self.beta * np.abs(edx)
        y = x - (1.0 - alpha(cutoff, dt)) * d
        return (y, edx), y


def pose_matches(pattern: str, name: str) -> bool:
    """Does ``pattern`` (a pose group ``head``/``eyes``, a glob or a name, any case) name
    the head/eye angle ``name``?"""
    p, n = pattern.strip().lower(), pose_name(name)
    if n is None:
        return False
    if p in POSE_GROUPS:
        return n in POSE_GROUPS[p]
    if any(ch in p for ch in "*?["):
        return fnmatchcase(n.lower(), p)
    return p == n.lower()


def pose_columns(anim: Animation) -> tuple[list[int], tuple[str, ...]]:
    """Columns of ``meta["pose"]`` that are head/eye angles, and their Live Link names."""
    names = [str(n) for n in anim.meta.get("pose_names", ())]
    cols = [j for j, n in enumerate(names) if pose_name(n) is not None]
    return cols, tuple(pose_name(names[j]) or names[j] for j in cols)


def clean_pose(anim: Animation, cleaner_for) -> Animation:
    """``anim`` with its head/eye angles (``meta["pose"]``) cleaned by ``cleaner_for(names)``
    (a fresh rotation cleaner for those angles); other pose columns unchanged. The angles
    are stepped on the frames that carry blendshapes: a tracking-loss row is a missing
    frame for them too (rule 1), whatever angles it holds."""
    pose = anim.meta.get("pose")
    cols, names = pose_columns(anim)
    if pose is None or not cols or len(pose) != anim.n_frames:
        return anim
    pose = np.array(pose, dtype=np.float64)  # (N, P) rad
    angles = pose[:, cols]
    angles[~anim.valid] = np.nan
    cleaned = cleaner_for(names).clean(Animation(anim.times, angles, names)).values
    keep = ~anim.valid
    pose[:, cols] = np.where(keep[:, None], pose[:, cols], cleaned)
    return Animation(anim.times, anim.values, anim.names, {**anim.meta, "pose": pose})
