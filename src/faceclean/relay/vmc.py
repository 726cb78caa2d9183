"""The VMC protocol (Virtual Motion Capture, OSC over UDP): blendshape frames <-> datagrams.

A frame is ``/VMC/Ext/Blend/Val (s name, f value)`` messages, then
``/VMC/Ext/Blend/Apply``, in one bundle or spread over loose messages and datagrams.
``/VMC/Ext/T (f seconds)`` gives the sender's time. Every other address (bones, root,
``/VMC/Ext/OK`` ...) passes through untouched: in the output bundle of the frame it came
with, or, in a datagram without blendshape messages, as that datagram unchanged.
Names are the ARKit "perfect sync" ones in any spelling ``channels.canonical`` accepts.

Head pose: ``/VMC/Ext/Bone/Pos (s bone, f px, py, pz, f qx, qy, qz, qw)`` for the bones
``Head``, ``LeftEye`` and ``RightEye`` (Unity's frame, faceclean.pose) becomes the frame's
pose (yaw, pitch, roll of each; NaN for a bone not sent) and is taken out of the
passthrough, so the encoder sends the cleaned rotation in its place, with the position
as received ((0, 0, 0) when the source had none: a Live Link or iFacialMocap stream).
Once a sender has sent a face frame, those bones are taken from its bone-only datagrams
too (held until the next Apply); before that, bone-only datagrams pass unchanged (a body
tracker's stream is not held back).
"""

from __future__ import annotations

import re
import struct

import numpy as np

from faceclean import pose as rotations
from faceclean.channels import canonical, pascal, to_side_suffix
from faceclean.relay import bounds, osc
from faceclean.relay.bounds import MAX_PENDING, MAX_PENDING_BYTES
from faceclean.relay.frame import Frame, Malformed

DEFAULT_PORT = 39539  # the VMC performer (receiver) port
VAL = b"/VMC/Ext/Blend/Val"
APPLY = b"/VMC/Ext/Blend/Apply"
TIME = b"/VMC/Ext/T"
BONE = b"/VMC/Ext/Bone/Pos"
POSE_BONES = ("Head", "LeftEye", "RightEye")  # each -> 3 of Frame.pose (yaw, pitch, roll)
NAME_STYLES = ("keep", "arkit", "pascal", "lr")
_APPLY_MSG = osc.message(APPLY.decode())
_VAL_HEAD = osc.pad(VAL) + osc.pad(b",sf")
_F32 = struct.Struct(">f")
# One Val message with (string, float) arguments: the name, then its float's 4 bytes.
_VAL_SF = re.compile(re.escape(_VAL_HEAD) + rb"([^\x00]*)\x00{1,4}(.{4})", re.DOTALL)


class Decoder:
    """Datagrams -> frames. Holds the values seen since the last Apply (loose messages)."""

    def __init__(self) -> None:
        self._faces = False  # this sender has sent a face frame (an Apply)
        self._clear()

    def _clear(self) -> None:
        self._vals: dict[str, float] = {}
        self._t: float | None = None
        self._passthrough: list[bytes] = []
        self._bytes = 0  # of the held names and passthrough messages
        self._bones: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {}  # pos, quat

    def feed(self, data: bytes) -> Frame | None:
        """A frame when this datagram holds an Apply; a passthrough-only frame when it
        holds no blendshape message at all; else None. Raises Malformed (state kept)."""
        vals: list[tuple[str, float]] = []
        other: list[bytes] = []
        bones: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {}
        raw_bones: list[bytes] = []
        t: float | None = None
        applied = False
        for address, start, end in osc.messages(data):  # parse all before changing state
            if address == VAL and (m := _VAL_SF.fullmatch(data, start, end)):  # fast path
                if len(m.group(1)) > bounds.MAX_NAME_BYTES:
                    raise Malformed(f"vmc: name longer than {bounds.MAX_NAME_BYTES} bytes")
                try:
                    vals.append((m.group(1).decode("utf-8"), _F32.unpack(m.group(2))[0]))
                except UnicodeDecodeError:
                    raise Malformed("vmc: name is not UTF-8") from None
            elif address == VAL:
                args = osc.arguments(data, start, end)
                if len(args) != 2 or not isinstance(args[0], str):
                    raise Malformed("vmc: Blend/Val needs (string, float)")
                value = args[1]
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise Malformed("vmc: Blend/Val value is not a number")
                vals.append((bounds.name(args[0], "vmc: name"), float(value)))
            elif address == APPLY:
                applied = True
            elif address == BONE and (bone := _pose_bone(data, start, end)) is not None:
                bones[bone[0]] = bone[1:]
                raw_bones.append(data[start:end])
            else:
                if address == TIME:
                    args = osc.arguments(data, start, end)
                    if len(args) == 1 and isinstance(args[0], float):
                        t = bounds.time(args[0])  # absurd times: the datagram is malformed
                other.append(data[start:end])
        if not vals and not applied:
            if t is not None:
                self._t = t
            if not bones or not self._faces:
                return Frame((), np.zeros(0), passthrough=(data,))
            self._bones.update(bones)  # head pose for the next Apply; the rest goes on
            return Frame((), np.zeros(0), passthrough=tuple(other)) if other else None
        self._bones.update(bones)
        self._vals.update(vals)
        self._passthrough.extend(other)
        self._bytes += sum(len(n) for n, _ in vals) + sum(len(o) for o in other)
        if t is not None:
            self._t = t
        if (
            len(self._vals) > MAX_PENDING
            or len(self._passthrough) > MAX_PENDING
            or self._bytes > MAX_PENDING_BYTES
        ):
            self._clear()
            raise Malformed("vmc: too many messages without Apply")
        if not applied:
            return None
        frame = Frame(
            tuple(self._vals),
            np.fromiter(self._vals.values(), np.float64, len(self._vals)),
            self._t,
            passthrough=tuple(self._passthrough),
        )
        if self._bones:
            frame.pose, frame.positions = _pose_of(self._bones)
        self._clear()
        self._faces = True
        return bounds.checked(frame)


def _pose_bone(data: bytes, start: int, end: int) -> tuple | None:
    """(bone, position (3,), quaternion (4,)) of a Bone/Pos message for a POSE_BONES bone;
    None for any other bone (it passes through). Raises Malformed for a bad one."""
    args = osc.arguments(data, start, end)
    if not args or args[0] not in POSE_BONES:
        return None
    nums = args[1:]
    if len(nums) != 7 or any(isinstance(a, bool) or not isinstance(a, int | float) for a in nums):
        raise Malformed("vmc: Bone/Pos needs (string, 7 floats)")
    return args[0], tuple(float(a) for a in nums[:3]), tuple(float(a) for a in nums[3:])


def _pose_of(bones: dict) -> tuple[np.ndarray, dict[str, tuple[float, float, float]]]:
    """(9,) yaw/pitch/roll of Head, LeftEye, RightEye (NaN: not sent), their positions."""
    pose = np.full(9, np.nan)
    names = [b for b in POSE_BONES if b in bones]
    angles = rotations.unity_angles(np.array([bones[b][1] for b in names]))  # (B, 3)
    for b, a in zip(names, angles, strict=True):
        i = 3 * POSE_BONES.index(b)
        pose[i : i + 3] = a
    return pose, {b: bones[b][0] for b in names}


def rename(name: str, style: str) -> str:
    """A channel name in an output style: keep, arkit (camelCase), pascal, lr (``_L``/``_R``)."""
    if style == "keep":
        return name
    c = canonical(name)
    if c is None:
        return name
    return {"arkit": c, "pascal": pascal(c), "lr": to_side_suffix(c)}[style]


class Encoder:
    """Frames -> one VMC bundle: passthrough elements, the Val messages, Apply.

    ``names``: the spelling of the names sent (``NAME_STYLES``); ``stamp``: add
    ``/VMC/Ext/T`` with the frame's time (float32 seconds: keep times small).
    """

    def __init__(self, names: str = "keep", stamp: bool = False) -> None:
        if names not in NAME_STYLES:
            raise ValueError(f"vmc names style {names!r} not in {NAME_STYLES}")
        self.style = names
        self.stamp = stamp
        self._heads: dict[str, bytes] = {}  # name -> i32 size + message up to its float

    def _head(self, name: str) -> bytes:
        head = self._heads.get(name)
        if head is None:
            body = _VAL_HEAD + osc.pad(rename(name, self.style).encode("utf-8"))
            head = struct.pack(">i", len(body) + 4) + body
            if len(self._heads) < 4 * MAX_PENDING:  # bounded: 2,048 x <= 160 bytes
                self._heads[name] = head
        return head

    def encode(self, frame: Frame) -> bytes:
        if not frame.is_face:
            if len(frame.passthrough) == 1:  # a datagram forwarded unchanged
                return frame.passthrough[0]
            return osc.bundle(list(frame.passthrough))
        floats = np.asarray(frame.values, ">f4").tobytes()  # (M,) big-endian f32
        parts = [osc.BUNDLE, osc.IMMEDIATE]
        elements = list(frame.passthrough)
        if frame.pose is not None:
            elements += _bone_messages(frame.pose, frame.positions or {})
        if self.stamp and frame.t is not None:
            elements.insert(0, osc.message(TIME.decode(), float(frame.t)))
        for e in elements:
            parts.append(struct.pack(">i", len(e)))
            parts.append(e)
        for i, name in enumerate(frame.names):
            parts.append(self._head(name))
            parts.append(floats[4 * i : 4 * i + 4])
        parts.append(struct.pack(">i", len(_APPLY_MSG)))
        parts.append(_APPLY_MSG)
        return b"".join(parts)


def _bone_messages(pose: np.ndarray, positions: dict) -> list[bytes]:
    """Bone/Pos messages for the bones whose 3 angles in ``pose`` (9,) are finite."""
    angles = np.asarray(pose, np.float64)[:9].reshape(-1, 3)  # (3, 3) yaw, pitch, roll
    sent = [i for i in range(len(angles)) if np.isfinite(angles[i]).all()]
    if not sent:
        return []
    quats = rotations.unity_quaternion(angles[sent])  # (B, 4)
    out = []
    for i, q in zip(sent, quats, strict=True):
        bone = POSE_BONES[i]
        p = positions.get(bone, (0.0, 0.0, 0.0))
        out.append(osc.message(BONE.decode(), bone, *(float(v) for v in (*p, *q))))
    return out
