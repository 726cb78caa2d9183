"""The iFacialMocap text stream (input only): ``name-value|name-value|...`` per datagram.

Values are percent (0-100) and become weights in [0, 1]; names use ``_L``/``_R``
(``eyeBlink_L``), mapped by ``channels.canonical``. Newer app versions write
``name&value``; both are read. Fields holding ``#`` (``=head#rx,ry,rz,tx,ty,tz``,
``rightEye#...``, ``leftEye#...``: degrees in the app's own axes) are not blendshapes and
are ignored. Packets carry no timestamp: the relay uses their arrival time.
"""

from __future__ import annotations

import numpy as np

from faceclean.relay import bounds
from faceclean.relay.frame import Frame, Malformed

DEFAULT_PORT = 49983


def decode(data: bytes) -> Frame:
    """One iFacialMocap datagram -> a Frame (names as sent, weights in [0, 1])."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise Malformed("ifacialmocap: not text") from None
    names: list[str] = []
    values: list[float] = []
    for token in text.split("|"):
        token = token.strip()
        if not token or "#" in token:
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
    return bounds.checked(Frame(tuple(names), np.array(values)))


class Decoder:
    """Stateless: every datagram is a whole frame."""

    def feed(self, data: bytes) -> Frame | None:
        return decode(data)
