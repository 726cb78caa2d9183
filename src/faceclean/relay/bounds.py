"""The relay's bounds: how much one sender can make it hold, and which packet values it takes.

Everything the relay keeps because of what it received is bounded here, so that no
sequence of datagrams, from one sender or many, grows its memory past a fixed size
(docs/RELAY.md, "Bounds"):

- decoder state per source address, for at most ``MAX_SENDERS`` addresses (the one
  heard least recently is forgotten first);
- per sender, at most ``MAX_PENDING`` VMC values or passthrough messages, and
  ``MAX_PENDING_BYTES`` bytes of them, while waiting for an Apply;
- per frame, at most ``MAX_NAMES`` channel names of at most ``MAX_NAME_BYTES`` bytes each
  (Live Link subjects and device ids too);
- every codec cache keyed by what a sender chose (name tuples, subjects) holds at most
  ``MAX_CACHE`` entries.

Worst case: 64 senders x 64 KiB pending + caches of 64 x 256 names x 128 bytes, about
6 MiB. Packet values: a time beyond ``MAX_TIME`` seconds is not a time (the datagram is
malformed); a value beyond float32 (which every output writes) is NaN, which the cleaner
holds like any non-finite cell.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Generic, TypeVar

import numpy as np

from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52
from faceclean.relay.frame import Frame, Malformed

MAX_SENDERS = 64  # source addresses with decoder state
MAX_PENDING = 512  # VMC values or passthrough messages held while waiting for Apply
MAX_PENDING_BYTES = 64 * 1024  # bytes of those, per sender
MAX_NAMES = 256  # channel names in one frame
MAX_NAME_BYTES = 128  # one channel name, Live Link subject or device id, UTF-8
MAX_CACHE = 64  # entries of each cache keyed by sender-chosen names
MAX_TIME = 1e9  # s (about 31 years); a packet time beyond is malformed
MAX_VALUE = float(np.finfo(np.float32).max)  # a value beyond is NaN

K = TypeVar("K")
V = TypeVar("V")


class Bounded(Generic[K, V]):
    """A dict of at most ``size`` entries; adding one more forgets the least recently used."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._d: OrderedDict[K, V] = OrderedDict()

    def get(self, key: K) -> V | None:
        value = self._d.get(key)
        if value is not None:
            self._d.move_to_end(key)
        return value

    def put(self, key: K, value: V) -> V:
        self._d[key] = value
        self._d.move_to_end(key)
        while len(self._d) > self.size:
            self._d.popitem(last=False)
        return value

    def __len__(self) -> int:
        return len(self._d)

    def values(self) -> list[V]:
        return list(self._d.values())


class ArkitColumns:
    """Where a frame's channels go in ARKit-52 order: (frame columns, ARKit positions) of
    ``ChannelMap(ARKIT52, names)``, cached per name tuple (senders choose the names)."""

    def __init__(self) -> None:
        self._cache: Bounded[tuple[str, ...], tuple[np.ndarray, np.ndarray]] = Bounded(MAX_CACHE)

    def __call__(self, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
        cols = self._cache.get(names)
        if cols is None:
            arkit = ChannelMap(ARKIT52, names)
            cols = self._cache.put(names, (arkit.cols, arkit.have))
        return cols

    def __len__(self) -> int:
        return len(self._cache)


def name(text: str, what: str = "name") -> str:
    """``text`` if it is at most MAX_NAME_BYTES of UTF-8, else Malformed."""
    if len(text) > MAX_NAME_BYTES or len(text.encode("utf-8", "surrogatepass")) > MAX_NAME_BYTES:
        raise Malformed(f"{what} longer than {MAX_NAME_BYTES} bytes")
    return text


def time(t: float | None) -> float | None:
    """A packet time in seconds: None stays None; non-finite or beyond MAX_TIME is Malformed."""
    if t is None:
        return None
    if not abs(t) <= MAX_TIME:
        raise Malformed(f"packet time {t!r} is not within +-{MAX_TIME:g} s")
    return float(t)


def checked(frame: Frame) -> Frame:
    """``frame`` within the bounds: names counted and sized, time bounded, values beyond
    float32 made NaN (cleaners hold them; outputs never overflow). Raises Malformed."""
    if len(frame.names) > MAX_NAMES:
        raise Malformed(f"{len(frame.names)} channels in a frame (at most {MAX_NAMES})")
    for n in frame.names:
        name(n)
    for label, text in (("subject", frame.subject), ("device id", frame.device)):
        if text is not None:
            name(text, label)
    return numbers(frame)


def numbers(frame: Frame) -> Frame:
    """``frame``'s time bounded and its values and pose beyond float32 made NaN (checked's
    part that depends on the numbers alone). Raises Malformed."""
    frame.t = time(frame.t)
    frame.values = _finite32(frame.values)
    if frame.pose is not None:
        frame.pose = _finite32(frame.pose)
    return frame


def _finite32(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, np.float64)
    over = np.abs(v) > MAX_VALUE  # NaN compares False, without a warning (numpy >= 1.24)
    return np.where(over, np.nan, v) if over.any() else v
