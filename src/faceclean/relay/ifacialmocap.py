"""The iFacialMocap text stream (input only): ``name-value|name-value|...`` per datagram.

Values are percent (0-100) and become weights in [0, 1]; names use ``_L``/``_R``
(``eyeBlink_L``), mapped by ``channels.canonical``. Newer app versions write
``name&value``; both are read. Fields holding ``#`` (``=head#rx,ry,rz,tx,ty,tz``,
``rightEye#...``, ``leftEye#...``: degrees in the app's own axes)
are not blendshapes: ``head#`` and ``leftEye#``/``rightEye#`` become the frame's pose
(rx, ry, rz as pitch, yaw, roll, degrees -> radians, the signs as sent; head position
tx, ty, tz is not used), other ``#`` fields are ignored. Packets carry no timestamp:
the relay uses their arrival time.
"""

from __future__ import annotations

import numpy as np

from faceclean.relay import bounds
from faceclean.relay.frame import Frame, Malformed

DEFAULT_PORT = 49983
ROTATIONS = {"head": 0, "lefteye": 3, "righteye": 6}  # field -> its first column of the pose


def decode(data: bytes) -> Frame:
    """One iFacialMocap datagram -> a Frame (names as sent, weights in [0, 1])."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise Malformed("ifacialmocap: not text") from None
    names: list[str] = []
    values: list[float] = []
    pose = np.full(9, np.nan)  # rad: yaw, pitch, roll of head, left eye, right eye
    for token in text.split("|"):
        token = token.strip()
        if "#" in token:
            _rotation(token, pose)
            continue
        if not token:
            continue
        name, sep, value = token.partition("&") if "&" in token else token.rpartition("-")
        if not sep or not name:
            raise Malformed(f"ifacialmocap: field {token[:40]!r} is not name-value")
        try:
            values.append(float(value) / 100.0)  # percent -> weight
        except ValueError:
            raise Malformed(f"ifacialmocap: value {value[:20]!r} is not a number") from None
        names.append(name)
    if not names:
        raise Malformed("ifacialmocap: no blendshape values")
    found = None if np.isnan(pose).all() else pose
    return bounds.checked(Frame(tuple(names), np.array(values), pose=found))


def _rotation(token: str, pose: np.ndarray) -> None:
    """A ``head#rx,ry,rz,...`` / ``leftEye#...`` field into ``pose`` (9,) in place."""
    name, _, rest = token.lstrip("=").partition("#")
    at = ROTATIONS.get(name.strip().lower())
    if at is None:
        return  # another # field: ignored
    parts = rest.split(",")
    try:
        rx, ry, rz = (float(v) for v in parts[:3])
    except ValueError:
        raise Malformed(f"ifacialmocap: {name[:20]!r} rotation is not 3 numbers") from None
    pose[at : at + 3] = np.radians([ry, rx, rz])  # yaw, pitch, roll


class Decoder:
    """Stateless: every datagram is a whole frame."""

    def feed(self, data: bytes) -> Frame | None:
        return decode(data)
