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

Quaternions are (..., 4) as (x, y, z, w); angles (..., 3) as (yaw, pitch, roll), rad.
scipy's Rotation does the arithmetic ("YXZ" intrinsic = Unity's Z-X-Y extrinsic).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

ORDER = "YXZ"  # intrinsic: yaw about Y, then pitch about X, then roll about Z


def unity_quaternion(ypr: np.ndarray) -> np.ndarray:
    """(..., 3) yaw, pitch, roll rad -> (..., 4) Unity (VMC) quaternion (x, y, z, w)."""
    a = np.asarray(ypr, np.float64)
    q = Rotation.from_euler(ORDER, a.reshape(-1, 3)).as_quat()  # (K, 4) x, y, z, w
    q = np.where(q[:, 3:] < 0, -q, q)  # one of the two signs: w >= 0
    return q.reshape(*a.shape[:-1], 4)


def unity_angles(q: np.ndarray) -> np.ndarray:
    """(..., 4) Unity quaternion (x, y, z, w) -> (..., 3) yaw, pitch, roll rad. A
    quaternion that is not finite or has no length gives NaN angles."""
    q = np.asarray(q, np.float64)
    flat = q.reshape(-1, 4)
    good = np.isfinite(flat).all(axis=1) & (np.linalg.norm(flat, axis=1) > 1e-9)
    out = np.full((len(flat), 3), np.nan)
    if good.any():
        out[good] = Rotation.from_quat(flat[good]).as_euler(ORDER)
    return out.reshape(*q.shape[:-1], 3)


def gltf_quaternion(ypr: np.ndarray) -> np.ndarray:
    """(..., 3) yaw, pitch, roll rad -> (..., 4) glTF rotation (x, y, z, w)."""
    return unity_quaternion(ypr) * np.array([1.0, -1.0, -1.0, 1.0])
