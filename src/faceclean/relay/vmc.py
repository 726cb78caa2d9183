"""The VMC protocol (Virtual Motion Capture, OSC over UDP): blendshape frames <-> datagrams.

A frame is ``/VMC/Ext/Blend/Val (s name, f value)`` messages, then
``/VMC/Ext/Blend/Apply``, in one bundle or spread over loose messages and datagrams.
``/VMC/Ext/T (f seconds)`` gives the sender's time. Every other address (bones, root,
``/VMC/Ext/OK`` ...) passes through untouched: in the output bundle of the frame it came
with, or, in a datagram without blendshape messages, as that datagram unchanged. A message
in a frame's bundle that is not well-formed OSC (``osc.well_formed``) is left out, since a
receiver's parser would refuse the whole bundle, and the frame with it.
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

import math
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
_T_HEAD = osc.pad(TIME) + osc.pad(b",f")
# One Val message with (string, float) arguments: the name, then its float's 4 bytes.
_VAL_SF = re.compile(re.escape(_VAL_HEAD) + rb"([^\x00]*)\x00{1,4}(.{4})", re.DOTALL)


class Decoder:
    """Datagrams -> frames. Holds the values seen since the last Apply (loose messages).

    A sender sends the same bundle every frame but for its floats. From the second
    datagram of one size that holds a whole frame by itself (nothing held before it), the
    decoder keeps its ``_Layout``; a later one from that sender whose other 32-bit words
    are the same is read from its floats alone (``_Layout.read``: no message is walked, no
    name checked again; the time and float32 bounds still apply), and gives the frame that
    a full parse would (a repeated name too). A repeated time or bone message keeps the
    earlier one's floats among the fixed words, so such a sender is parsed in full.
    """

    def __init__(self) -> None:
        self._faces = False  # this sender has sent a face frame (an Apply)
        self._layout: _Layout | None = None
        self._size = -1  # bytes of the last datagram that came with nothing held
        self._clear()

    def _clear(self) -> None:
        self._vals: dict[str, float] = {}
        self._t: float | None = None
        self._passthrough: list[bytes] = []
        self._bytes = 0  # of the held names and passthrough messages
        self._bones: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {}  # pos, quat

    def _holds(self) -> bool:
        return bool(self._vals or self._passthrough or self._bones) or self._t is not None

    def feed(self, data: bytes) -> Frame | None:
        """A frame when this datagram holds an Apply; a passthrough-only frame when it
        holds no blendshape message at all; else None. Raises Malformed (state kept)."""
        clear = not self._holds()  # nothing held from earlier datagrams
        if clear and self._layout is not None:
            frame = self._layout.read(data)
            if frame is not None:
                return frame
        # the layout this datagram would leave: gathered from the second whole frame of a
        # size on (a first datagram, or a sender whose sizes vary, pays nothing for it)
        plan = _Plan(len(data)) if clear and len(data) == self._size else None
        self._size = len(data) if clear else -1
        vals: list[tuple[str, float]] = []
        other: list[bytes] = []
        bones: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {}
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
                if plan is not None:
                    plan.value(vals[-1][0], m.start(2))
            elif address == VAL:
                args = osc.arguments(data, start, end)
                if len(args) != 2 or not isinstance(args[0], str):
                    raise Malformed("vmc: Blend/Val needs (string, float)")
                value = args[1]
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise Malformed("vmc: Blend/Val value is not a number")
                vals.append((bounds.name(args[0], "vmc: name"), float(value)))
                plan = None  # a value not in the usual form: read in full each time
            elif address == APPLY:
                applied = True
            elif address == BONE and (bone := _pose_bone(data, start, end)) is not None:
                bones[bone[0]] = bone[1:]
                if plan is not None:
                    plan.bone(bone[0], data, start, end)
            else:
                if address == TIME:
                    args = osc.arguments(data, start, end)
                    if len(args) == 1 and isinstance(args[0], float):
                        t = bounds.time(args[0])  # absurd times: the datagram is malformed
                        if plan is not None:
                            plan.time(data, start, end)
                elif not osc.well_formed(data, start, end):
                    continue  # left out: a receiver's parser would refuse the whole bundle
                other.append(data[start:end])
                if plan is not None:
                    plan.span(start, end)
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
        frame = bounds.checked(frame)
        if plan is not None:
            self._layout = plan.layout(data, frame.names)
        return frame


class _Plan:
    """Where the floats of one datagram are, gathered while it is parsed (byte offsets)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.ok = size % 4 == 0  # OSC packets are whole 32-bit words
        self.values: dict[str, int] = {}  # name -> its float (the last one sent wins)
        self.t: int | None = None
        self.bones: dict[str, int] = {}  # bone -> its 7 floats (position, quaternion)
        self.spans: list[tuple[int, int]] = []  # the passthrough messages
        self.floats: list[int] = []  # word index of every Val's float, repeats too

    def value(self, name: str, at: int) -> None:
        self.ok &= at % 4 == 0
        self.floats.append(at // 4)
        self.values[name] = at  # a repeated name: its first place, its last value (a dict)

    def time(self, data: bytes, start: int, end: int) -> None:
        self.ok &= data[start:end] == _T_HEAD + data[end - 4 : end]  # /VMC/Ext/T ,f
        self.t = end - 4

    def bone(self, bone: str, data: bytes, start: int, end: int) -> None:
        head = osc.pad(BONE) + osc.pad(b",sfffffff") + osc.pad(bone.encode())
        self.ok &= data[start : end - 28] == head
        self.bones[bone] = end - 28

    def span(self, start: int, end: int) -> None:
        self.spans.append((start, end))

    def layout(self, data: bytes, names: tuple[str, ...]) -> _Layout | None:
        if not self.ok or tuple(self.values) != names:
            return None
        floats = list(self.floats)
        if self.t is not None:
            floats.append(self.t // 4)
        for at in self.bones.values():
            floats += range(at // 4, at // 4 + 7)
        fixed = np.ones(self.size // 4, bool)
        fixed[floats] = False
        fixed = np.flatnonzero(fixed)
        return _Layout(self, names, fixed, np.frombuffer(data, ">u4")[fixed].copy())


class _Layout:
    """A whole-frame datagram's 32-bit words but its floats, and where those floats are."""

    def __init__(self, plan: _Plan, names: tuple, fixed: np.ndarray, words: np.ndarray) -> None:
        self.size, self.names, self.spans = plan.size, names, tuple(plan.spans)
        self.fixed, self.words = fixed, words  # (K,) word indices, (K,) their words
        self.values = np.array([v // 4 for v in plan.values.values()], np.intp)  # (M,)
        self.t = None if plan.t is None else plan.t // 4
        self.bones = tuple(plan.bones)
        self.bone_at = np.array([[a // 4 + k for k in range(7)] for a in plan.bones.values()])

    def read(self, data: bytes) -> Frame | None:
        """The frame of ``data`` if it has this layout, else None. Raises Malformed."""
        if len(data) != self.size:
            return None
        words = np.frombuffer(data, ">u4")
        if not np.array_equal(words[self.fixed], self.words):
            return None
        floats = words.view(">f4")
        t = None if self.t is None else float(floats[self.t])
        frame = Frame(
            self.names,
            floats[self.values].astype(np.float64),
            t,
            passthrough=tuple(data[a:b] for a, b in self.spans),
        )
        if self.bones:
            b = floats[self.bone_at].astype(np.float64).tolist()  # (B, 7)
            bones = {n: (tuple(v[:3]), tuple(v[3:])) for n, v in zip(self.bones, b, strict=True)}
            frame.pose, frame.positions = _pose_of(bones)
        return bounds.numbers(frame)


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
    pose = [math.nan] * 9
    names = [b for b in POSE_BONES if b in bones]
    for b in names:
        i = 3 * POSE_BONES.index(b)
        pose[i : i + 3] = rotations.unity_angles_one(bones[b][1])
    return np.array(pose), {b: bones[b][0] for b in names}


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
        self._at: dict[str, tuple[float, float, float]] = {}  # bone -> last finite position

    def _head(self, name: str) -> bytes:
        head = self._heads.get(name)
        if head is None:
            body = _VAL_HEAD + osc.pad(rename(name, self.style).encode("utf-8"))
            head = struct.pack(">i", len(body) + 4) + body
            if len(self._heads) < 4 * MAX_PENDING:  # bounded: 2,048 x <= 160 bytes
                self._heads[name] = head
        return head

    def encode(self, frame: Frame) -> bytes:
        """One datagram; nothing NaN or infinite goes out (docs/ROBUSTNESS.md, class 12):
        a Val whose value is not finite within float32 is left out (the receiver keeps
        its last), a pose bone's position is the last finite one sent for it ((0, 0, 0)
        before any), a passthrough message with a NaN or infinite float is left out
        (b"": nothing of the datagram is left to send)."""
        if not frame.is_face:
            if len(frame.passthrough) == 1:  # a datagram forwarded unchanged
                return osc.finite_part(frame.passthrough[0])
            kept = [e for e in frame.passthrough if osc.finite(e)]
            return osc.bundle(kept) if kept else b""
        values = np.asarray(frame.values, np.float64)
        floats = values.astype(">f4").tobytes()  # (M,) big-endian f32
        good = np.abs(values) <= bounds.MAX_VALUE  # NaN compares False
        parts = [osc.BUNDLE, osc.IMMEDIATE]
        elements = [e for e in frame.passthrough if osc.finite(e)]
        if frame.pose is not None:
            elements += _bone_messages(frame.pose, self._positions(frame.positions or {}))
        if self.stamp and frame.t is not None:
            elements.insert(0, osc.message(TIME.decode(), float(frame.t)))
        for e in elements:
            parts.append(struct.pack(">i", len(e)))
            parts.append(e)
        for i, name in enumerate(frame.names):
            if good[i]:
                parts.append(self._head(name))
                parts.append(floats[4 * i : 4 * i + 4])
        parts.append(struct.pack(">i", len(_APPLY_MSG)))
        parts.append(_APPLY_MSG)
        return b"".join(parts)

    def _positions(self, given: dict) -> dict[str, tuple[float, float, float]]:
        """Each pose bone's position to send: as received when finite within float32,
        else the last such one sent for that bone (held), else (0, 0, 0)."""
        for bone, p in given.items():
            if bone in POSE_BONES and all(abs(float(v)) <= bounds.MAX_VALUE for v in p):
                self._at[bone] = tuple(float(v) for v in p)
        return self._at


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
