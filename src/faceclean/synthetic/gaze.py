"""Gaze: the eyeballs turned by the ARKit eyeLook weights.

ICT's eyeLook shapes move the lids only (their deltas on the eyeballs are zero), so a face
rendered with eyeLook weights keeps its irises straight ahead. ``Eyes(head, base)`` turns
each eyeball about its centre (the middle of its box, cm, for the identity ``base``):

    yaw   = H_DEG (out - in), toward the eye's own side (outward),   deg
    pitch = UP_DEG up - DOWN_DEG down, + up,                          deg

with out, in, up, down that eye's eyeLook weights. ARKit publishes no degrees per unit
weight; these are a rig's usual ranges (an eye turns about 30 deg either way). Left is
the subject's left (+x in head space).
"""

from __future__ import annotations

import numpy as np

from faceclean.channels import ARKIT52

H_DEG, UP_DEG, DOWN_DEG = 30.0, 25.0, 30.0  # deg at eyeLook weight 1
SIDES = ("Left", "Right")  # +x, -x in head space
_W = {side: [ARKIT52.index(f"eyeLook{d}{side}") for d in ("Out", "In", "Up", "Down")]
      for side in SIDES}  # fmt: skip


def eye_angles(weights: np.ndarray, side: str) -> tuple[float, float]:
    """(yaw toward +x, pitch up), deg, of one eye for ARKit ``weights`` (52,)."""
    out, inward, up, down = np.nan_to_num(np.asarray(weights, np.float64)[_W[side]])
    outward = H_DEG * (out - inward)
    return (outward if side == "Left" else -outward), UP_DEG * up - DOWN_DEG * down


def _turn(yaw: float, pitch: float) -> np.ndarray:
    """(3, 3): the front axis +z turned ``yaw`` deg toward +x, then ``pitch`` deg toward +y."""
    y, p = np.radians([yaw, pitch])
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    return (ry @ rx.T).astype(np.float32)  # rx.T: +pitch lifts +z toward +y


class Eyes:
    """Both eyeballs of one identity, turned per frame (see the module docstring)."""

    def __init__(self, head, base: np.ndarray) -> None:
        v = base.reshape(-1, 3)  # (V, 3) cm, the identity's neutral
        on_eye = ~np.isnan(head.eye_angle)
        self.index = {s: np.flatnonzero(on_eye & (np.sign(head.neutral[:, 0]) == sign))
                      for s, sign in zip(SIDES, (1, -1), strict=True)}  # fmt: skip
        self.centre = {s: (v[i].min(0) + v[i].max(0)) / 2 for s, i in self.index.items()}

    def turn(self, v: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """``v`` (V, 3) cm with each eyeball turned by ``weights`` (52,) (in place)."""
        for side, idx in self.index.items():
            c = self.centre[side]
            v[idx] = (v[idx] - c) @ _turn(*eye_angles(weights, side)).T + c
        return v
