"""The messages both pages share: choose the cleaner and its settings, save and load the
CLI's files, drop the calibration, the guided calibration's panel (ui/guided.py: each
mode makes its ``Panel`` as ``guided``). ``Offline`` (ui/offline.py) and ``Live``
(ui/live.py) add what their mode does with a new ``Tuning`` (``apply``) and their own
messages (``on_<type>``).

Every message is a JSON object ``{"type": ..., "seq": n, ...}``; each field is checked
here (kind, length, range) before anything acts on it, and a refusal is the CLI's own
one-line FacecleanError, sent back as ``{"type": "error", "for": type, "message": ...}``.
A change is answered by a ``state`` message to every open page (``Tuning.describe``).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from faceclean.adaptation import check_tracker
from faceclean.adjust import Adjust
from faceclean.channels import ARKIT52, DEFAULT_TRACKER, GROUPS, TRACKERS
from faceclean.errors import FacecleanError
from faceclean.io.paths import verb
from faceclean.ui.server import Client
from faceclean.ui.tuning import MAX_ITEMS, MAX_TEXT, Tuning

MAX_PATH = 4096  # characters of a file name from the page


class Base:
    """Clients, the current ``Tuning`` and the shared messages."""

    mode = "?"
    MESSAGES: tuple[str, ...] = ("set", "save", "load", "uncalibrate", "guided")
    guided: Any = None  # the guided calibration's panel (ui/guided.py), made by the mode

    def __init__(self, tuning: Tuning, say: Callable[[str], None] | None = None) -> None:
        self.say = say  # what the command prints: the CLI's callback (None: nothing)
        self.tuning = tuning.with_choice()
        self.lock = threading.RLock()  # the tuning and the clients
        self.clients: list[Client] = []
        self._mesh: bytes | None = None  # the face's payload as JSON (report/payload.py)

    # -- clients ------------------------------------------------------------------------
    def attach(self, client: Client) -> None:
        client.send(self.hello())  # first: pushes to the page only follow it
        with self.lock:
            self.clients.append(client)

    def detach(self, client: Client) -> None:
        with self.lock:
            if client in self.clients:
                self.clients.remove(client)

    def broadcast(self, message: dict[str, Any]) -> None:
        for client in list(self.clients):
            client.send(message)

    def broadcast_bytes(self, data: bytes) -> None:
        for client in list(self.clients):
            client.send_bytes(data)

    def mesh(self) -> bytes:
        """The face the page draws (``/mesh.json``: fetched beside the live channel, so
        that its first message stays small), built once."""
        import json

        from faceclean.face.mesh import stylised
        from faceclean.report import payload

        if self._mesh is None:
            self._mesh = json.dumps(payload.mesh(stylised()), separators=(",", ":")).encode()
        return self._mesh

    def hello(self) -> dict[str, Any]:
        """The first message: what the page needs to draw its controls."""
        from faceclean import filters
        from faceclean.filters import presets

        return {
            "type": "hello",
            "mode": self.mode,
            "channels": list(ARKIT52),
            "groups": {g: sorted(m, key=ARKIT52.index) for g, m in GROUPS.items()},
            "methods": list(filters.METHODS),
            "presets": presets.shipped(),
            "trackers": list(TRACKERS),  # --tracker's names
            "state": self.tuning.describe(),
            "guided": None if self.guided is None else self.guided.hello(),
        }

    # -- messages -----------------------------------------------------------------------
    def handle(self, client: Client, message: dict[str, Any]) -> None:
        kind = message["type"]
        if kind not in self.MESSAGES:
            raise FacecleanError(
                f"unknown message {kind[:40]!r} (known: {', '.join(self.MESSAGES)})"
            )
        getattr(self, "on_" + kind)(client, message)

    def use(self, tuning: Tuning, seq: int | None = None, answers: str | None = None) -> None:
        """Make ``tuning`` current (already checked), let the mode act on it, tell the pages.
        ``answers``: the message type it answers (a later refusal says it as ``for``).
        The mode's ``apply`` refuses it by raising: then nothing changes."""
        with self.lock, np.errstate(all="ignore"):  # results are checked, not warned about
            self.apply(tuning)
            self.tuning = tuning
        self.broadcast({"type": "state", "seq": seq, **tuning.describe()})

    def apply(self, tuning: Tuning) -> None:
        """What the mode does with a new tuning (raise FacecleanError to refuse it)."""

    def on_set(self, client: Client, m: dict[str, Any]) -> None:
        words = text(m, "words", optional=True)
        items = texts(m, "items")
        tracker = text(m, "tracker", optional=True)
        self.use(self.tuning.changed(words, items, tracker), seq(m), "set")

    def on_save(self, client: Client, m: dict[str, Any]) -> None:
        what, path = choice(m, "what", ("preset", "levels")), text(m, "path", limit=MAX_PATH)
        with self.lock:
            tuning = self.tuning
        rest: list[str] = []
        replaced = verb(path) == "replaced"  # said on the page, never in silence
        if what == "preset":
            rest = tuning.save_preset(path)
        else:
            tuning.save_levels(path)
            if tuning.calibration is not None:
                tuning = tuning.calibrated(tuning.calibration, path)
                with self.lock:
                    self.tuning = tuning
        # the state first: a page that reads its note has the command that names the file
        self.broadcast({"type": "state", "seq": seq(m), **tuning.describe()})
        client.send({"type": "saved", "seq": seq(m), "what": what, "path": path, "rest": rest,
                     "replaced": replaced})  # fmt: skip

    def on_load(self, client: Client, m: dict[str, Any]) -> None:
        what, path = choice(m, "what", ("preset", "levels")), text(m, "path", limit=MAX_PATH)
        if what == "preset":
            self.use(self.tuning.changed(path, [], self.tuning.tracker), seq(m), "load")
        else:
            adjust = Adjust.load(path)
            check_tracker(adjust, self.tuning.tracker or DEFAULT_TRACKER, path)  # as --calibration
            self.use(self.tuning.calibrated(adjust, path).with_choice(), seq(m), "load")

    def on_uncalibrate(self, client: Client, m: dict[str, Any]) -> None:
        self.use(self.tuning.calibrated(None).with_choice(), seq(m), "uncalibrate")

    def on_guided(self, client: Client, m: dict[str, Any]) -> None:
        if self.guided is None:
            raise FacecleanError("guided calibration: not on this page")
        self.guided.handle(client, m, seq(m))


# -- field checks ----------------------------------------------------------------------------
def seq(m: dict[str, Any]) -> int | None:
    s = m.get("seq")
    return s if isinstance(s, int) and not isinstance(s, bool) and abs(s) < 2**53 else None


def text(m: dict[str, Any], key: str, *, optional: bool = False, limit: int = MAX_TEXT) -> Any:
    v = m.get(key)
    if v is None and optional:
        return None
    if not isinstance(v, str) or not v.strip():
        raise FacecleanError(f"{key}: expected a text")
    if len(v) > limit or "\x00" in v:
        raise FacecleanError(f"{key}: at most {limit} characters, no NUL")
    try:  # JSON's "\ud800" is a lone surrogate: no file name, no UTF-8 text holds it
        v.encode("utf-8")
    except UnicodeEncodeError as e:
        raise FacecleanError(f"{key}: not valid Unicode (a lone surrogate at {e.start})") from None
    return v.strip()


def texts(m: dict[str, Any], key: str) -> list[str]:
    v = m.get(key, [])
    if not isinstance(v, list) or len(v) > MAX_ITEMS:
        raise FacecleanError(f"{key}: expected a list of at most {MAX_ITEMS} texts")
    return [text({key: x}, key) for x in v]


def number(
    m: dict[str, Any], key: str, lo: float, hi: float, default: float | None = None
) -> float:
    v = m.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise FacecleanError(f"{key}: expected a number")
    if not lo <= v <= hi:
        raise FacecleanError(f"{key}: must be between {lo:g} and {hi:g} (got {v:g})")
    return float(v)


def choice(m: dict[str, Any], key: str, allowed: tuple[str, ...]) -> str:
    v = m.get(key)
    if v not in allowed:
        raise FacecleanError(f"{key}: one of {', '.join(allowed)}")
    return v
