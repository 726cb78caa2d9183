"""Live Link Face UDP, protocol version 6: packets <-> frames, and ``.gesichter`` recordings.

One packet, big-endian (../shared/data/README.md):
``u8 version(=6)``, ``i32 len`` + device id, ``i32 len`` + subject name,
``i32 frame_number``, ``f32 sub_frame``, ``i32 rate_numerator``, ``i32 rate_denominator``,
``u8 count`` (61; 52 is accepted: no angles), ``count x f32``: 52 blendshapes in ARKit
order, then the 9 head/eye angles (``POSE_NAMES``). A head or eye whose three angles are
all exactly 0 is not tracked (the app sends zeros with head rotation off): its angles
decode as NaN (absent: no VMC bone is sent for it) and encode back as 0.

Time of a packet: t = (frame_number + sub_frame) * denominator / numerator seconds.
The frame number, sub-frame and rate are the tracker's timecode: a decoded frame keeps
them (``Frame.timecode``) and the encoder writes them back unchanged, so a relayed,
recorded or replayed stream carries the tracker's own timecode. A frame without one
(VMC, iFacialMocap, a take file) gets frame numbers of its time at ``OUT_RATE``.
"""

from __future__ import annotations

import gzip
import io
import os
import struct
import zlib
from pathlib import Path

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.relay import bounds
from faceclean.relay.frame import Frame, Malformed

VERSION = 6
DEFAULT_PORT = 11111
N_SHAPES = 52
N_POSE = 9
_TIMING = struct.Struct(">ifiiB")  # frame_number, sub_frame, rate num, rate den, count
_I32 = struct.Struct(">i")
_BE_F32 = np.dtype(">f4")
OUT_RATE = (60, 1)  # frames per second of the frame numbers we write: 60/1


def _string(data: bytes, at: int) -> tuple[str, int]:
    if at + 4 > len(data):
        raise Malformed("livelink: truncated packet")
    (n,) = _I32.unpack_from(data, at)
    at += 4
    if n < 0 or at + n > len(data):
        raise Malformed("livelink: bad string length")
    if n > bounds.MAX_NAME_BYTES:
        raise Malformed(f"livelink: subject or device id over {bounds.MAX_NAME_BYTES} bytes")
    try:
        return data[at : at + n].decode("utf-8"), at + n
    except UnicodeDecodeError:
        raise Malformed("livelink: string is not UTF-8") from None


def decode(data: bytes) -> Frame:
    """One Live Link Face v6 packet -> a Frame (ARKit-52 names, pose, subject, time)."""
    if not data or data[0] != VERSION:
        raise Malformed(f"livelink: not a protocol {VERSION} packet")
    device, at = _string(data, 1)
    subject, at = _string(data, at)
    if at + _TIMING.size > len(data):
        raise Malformed("livelink: truncated packet")
    number, sub, num, den, count = _TIMING.unpack_from(data, at)
    at += _TIMING.size
    if count not in (N_SHAPES, N_SHAPES + N_POSE) or at + 4 * count != len(data):
        raise Malformed(f"livelink: {count} values in a {len(data)}-byte packet")
    if num < 0 or den < 0:  # no rate at all (0) falls back to arrival time; a negative one
        raise Malformed(f"livelink: frame rate {num}/{den} is negative")  # means nothing
    floats = np.frombuffer(data, _BE_F32, count, at).astype(np.float64)  # (count,)
    t = (number + float(sub)) * den / num if num > 0 and den > 0 else None
    pose = floats[N_SHAPES:].copy() if count > N_SHAPES else None
    if pose is not None:  # a rotation of exactly (0, 0, 0): not tracked (the app's setting)
        off = (pose.reshape(3, 3) == 0.0).all(axis=1)
        pose.reshape(3, 3)[off] = np.nan
    timecode = (number, float(sub), num, den) if t is not None else None
    frame = Frame(ARKIT52, floats[:N_SHAPES], t, pose, (), subject, device, timecode)
    return bounds.checked(frame)  # a non-finite or absurd time makes the packet malformed


def timecode_at(seconds: float, rate: tuple[int, int] = OUT_RATE) -> tuple[int, float, int, int]:
    """A timecode (frame number, sub-frame, num, den) for a time in seconds at ``rate``."""
    num, den = rate
    x = seconds * num / den  # frames
    number = int(np.floor(x))
    return number, float(x - number), num, den


class Decoder:
    """Stateless: every datagram is a whole frame."""

    def feed(self, data: bytes) -> Frame | None:
        return decode(data)


class Encoder:
    """Frames -> Live Link Face v6 packets (61 floats: 52 blendshapes, then 9 angles).

    Channels the frame lacks are 0; its pose passes through (zeros when it has none, or
    for an angle it lacks). The frame's own timecode is written as it is; without one,
    frame numbers count 60 fps frames of the frame's time (``OUT_RATE``).
    """

    def __init__(self, subject: str = "faceclean", device: str = "faceclean") -> None:
        self.subject = subject
        self.device = device
        # caches keyed by what senders chose: bounded (relay/bounds.py)
        self._index = bounds.ArkitColumns()  # a frame's names -> its ARKit columns
        self._heads: bounds.Bounded[tuple[str, str], bytes] = bounds.Bounded(bounds.MAX_CACHE)
        self._count = 0

    def _head(self, device: str, subject: str) -> bytes:
        key = (device, subject)
        head = self._heads.get(key)
        if head is None:
            d, s = device.encode("utf-8"), subject.encode("utf-8")
            head = bytes([VERSION]) + _I32.pack(len(d)) + d + _I32.pack(len(s)) + s
            self._heads.put(key, head)
        return head

    def encode(self, frame: Frame) -> bytes:
        floats = np.zeros(N_SHAPES + N_POSE)
        src, dst = self._index(frame.names)
        floats[dst] = frame.values[src]
        if frame.pose is not None:
            pose = np.nan_to_num(frame.pose[:N_POSE])
            floats[N_SHAPES : N_SHAPES + len(pose)] = pose
        num, den = OUT_RATE
        x = frame.t * num / den if frame.t is not None else None  # frames, 60 fps
        if frame.timecode is not None:  # the tracker's own, unchanged
            number, sub, num, den = frame.timecode
        elif x is not None and abs(x) < 2.0**52:  # else no exact frame number: count on
            number = int(np.floor(x))
            sub = x - number
        else:
            number, sub = self._count, 0.0
        number = (number + 2**31) % 2**32 - 2**31  # wrap into i32
        self._count = number + 1
        head = self._head(frame.device or self.device, frame.subject or self.subject)
        sub = sub if abs(sub) <= bounds.MAX_VALUE else 0.0  # NaN compares False
        timing = _TIMING.pack(number, sub, num, den, N_SHAPES + N_POSE)
        # nothing NaN or infinite goes out: a value not finite within float32 is 0, the
        # value of a channel or angle the frame lacks (docs/ROBUSTNESS.md, class 12)
        floats = np.where(np.abs(floats) <= bounds.MAX_VALUE, floats, 0.0)
        return head + timing + floats.astype(_BE_F32).tobytes()


MAX_RECORDING = 256 << 20  # bytes a recording may unpack to (an hour at 60 fps: ~60 MB)


def read_recording(path: str | os.PathLike) -> list[bytes]:
    """The packets of a ``.gesichter`` recording (gzip: u8 version, u32 count, then
    per packet u32 size + the packet exactly as sent)."""
    from faceclean.io import source

    p = Path(path)
    raw = source.read_bytes(p, what="recording")  # a regular file, bounded
    try:  # unpacked bounded too (a gzip bomb)
        with gzip.GzipFile(fileobj=io.BytesIO(raw)) as f:
            blob = f.read(MAX_RECORDING + 1)
    except (OSError, EOFError, zlib.error) as e:
        raise FacecleanError(f"{p.name}: not a gzip .gesichter recording ({e})") from None
    if len(blob) > MAX_RECORDING:
        raise FacecleanError(f"{p.name}: unpacks to over {source.size_text(MAX_RECORDING)}")
    if len(blob) < 5:
        raise FacecleanError(f"{p.name}: truncated recording")
    (count,) = struct.unpack_from(">I", blob, 1)
    packets, at = [], 5
    for _ in range(count):
        if at + 4 > len(blob):
            raise FacecleanError(f"{p.name}: truncated recording")
        (size,) = struct.unpack_from(">I", blob, at)
        if at + 4 + size > len(blob):
            raise FacecleanError(f"{p.name}: truncated recording")
        packets.append(blob[at + 4 : at + 4 + size])
        at += 4 + size
    return packets
