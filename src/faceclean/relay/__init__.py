"""The live relay: receive a face stream, clean each frame as it arrives, send it on.

Codecs are pure bytes <-> :class:`~faceclean.relay.frame.Frame` (``vmc``, ``livelink``,
``ifacialmocap``, on top of the small ``osc`` codec); ``url`` parses endpoints;
``loop`` is the socket loop (newest frame only, counters, latency); ``replay`` streams a
recorded take. See docs/RELAY.md.
"""

from __future__ import annotations

from faceclean.relay.frame import Frame, Malformed
from faceclean.relay.loop import Relay, Stats
from faceclean.relay.url import Endpoint, parse

__all__ = ["Endpoint", "Frame", "Malformed", "Relay", "Stats", "parse"]
