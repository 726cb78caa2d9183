"""Head and eye rotations: Live Link's yaw/pitch/roll angles <-> quaternions.

The convention, once (docs/FORMATS.md, "Head pose"):

- Live Link Face's angles are Unity-style Euler angles in radians: a left-handed frame
  with +X the subject's right, +Y up, +Z forward (out of the face); yaw about +Y, pitch
  about +X, roll about +Z, applied roll, then pitch, then yaw (Unity's Z-X-Y order:
  q = q_yaw q_pitch q_roll). Checked on the shared takes: a positive LeftEyeYaw goes
  with eyeLookInLeft (the left eye turning to the subject's right) and a positive pitch
  with eyeLookDown*, as that frame says; the roll's sign follows the same frame.
- VMC (Unity) takes that rotation as it is: ``/VMC/Ext/Bone/Pos`` quaternions are
  (x, y, z, w) in Unity's frame.
- glTF is right-handed with the face looking along +Z and +X its left: Unity's frame
  with X mirrored, so the glTF quaternion is (x, -y, -z, w) of the Unity one.

Quaternions are (..., 4) as (x, y, z, w); angles (..., 3) as (yaw, pitch, roll), rad;
the same rotations as scipy's ``Rotation.from_euler("YXZ", ...)`` (intrinsic Y-X-Z =
Unity's Z-X-Y extrinsic; the tests check it), written out in numpy because the relay
converts every frame (about 3x faster than scipy per call, measured here).
"""

from __future__ import annotations

import math

import numpy as np

ORDER = "YXZ"  # intrinsic: yaw about Y, then pitch about X, then roll about Z


def unity_quaternion(ypr: np.ndarray) -> np.ndarray:
    """(..., 3) yaw, pitch, roll rad -> (..., 4) Unity (VMC) quaternion (x, y, z, w), w >= 0."""
    a = np.asarray(ypr, np.float64) / 2.0
    sy, cy = np.sin(a[..., 0]), np.cos(a[..., 0])
    sx, cx = np.sin(a[..., 1]), np.cos(a[..., 1])
    sz, cz = np.sin(a[..., 2]), np.cos(a[..., 2])
    q = np.stack(  # q_yaw (about Y) * q_pitch (about X) * q_roll (about Z)
        [
            cy * sx * cz + sy * cx * sz,
            sy * cx * cz - cy * sx * sz,
            cy * cx * sz - sy * sx * cz,
            cy * cx * cz + sy * sx * sz,
        ],
        axis=-1,
    )
    return np.where(q[..., 3:] < 0, -q, q)  # one of the two signs


def unity_angles(q: np.ndarray) -> np.ndarray:
    """(..., 4) Unity quaternion (x, y, z, w) -> (..., 3) yaw, pitch, roll rad (pitch in
    [-pi/2, pi/2]). A quaternion that is not finite or has no length gives NaN angles."""
    q = np.asarray(q, np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        x, y, z, w = np.moveaxis(np.where(n > 1e-9, q / n, np.nan), -1, 0)
    # the rotation matrix R = R_y R_x R_z: R02, R22 give yaw, R12 pitch, R10, R11 roll
    yaw = np.arctan2(2 * (x * z + w * y), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(-2 * (y * z - w * x), -1.0, 1.0))
    roll = np.arctan2(2 * (x * y + w * z), 1 - 2 * (x * x + z * z))
    return np.stack([yaw, pitch, roll], axis=-1)


def unity_angles_one(q: tuple[float, float, float, float]) -> tuple[float, float, float]:
    """``unity_angles`` of one quaternion (x, y, z, w), in Python floats: the relay's
    per-frame path, where numpy's cost per call on 4 numbers is some 20x the arithmetic."""
    n = math.sqrt(sum(v * v for v in q)) if all(math.isfinite(v) for v in q) else math.nan
    if not n > 1e-9:
        return (math.nan, math.nan, math.nan)
    x, y, z, w = (v / n for v in q)
    yaw = math.atan2(2 * (x * z + w * y), 1 - 2 * (x * x + y * y))
    pitch = math.asin(min(1.0, max(-1.0, -2 * (y * z - w * x))))
    roll = math.atan2(2 * (x * y + w * z), 1 - 2 * (x * x + z * z))
    return (yaw, pitch, roll)


def gltf_quaternion(ypr: np.ndarray) -> np.ndarray:
    """(..., 3) yaw, pitch, roll rad -> (..., 4) glTF rotation (x, y, z, w)."""
    return unity_quaternion(ypr) * np.array([1.0, -1.0, -1.0, 1.0])
