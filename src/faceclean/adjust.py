"""Per-channel level mapping, applied to the raw tracker values BEFORE the cleaner.

One equation per channel (x the tracker value, y what the cleaner sees)::

    x = scale * x                      # --scale (e.g. 0.01 for a take in percent)
    u = gain * (x - offset)            # zero point and scale
    u = sign(u) * |u| ** curve         # exponent: curve < 1 lifts small values, > 1 damps them
    y = clip(u, lo, hi)                # clamp = (lo, hi); [0, 1] unless one is set
    y = 0  where the channel is off    # muted (a missing frame, NaN, stays NaN)

Levels stay in ARKit's range: a channel not at the identity (scale 1, gain 1, offset 0,
curve 1, on: bit-for-bit unchanged, its arithmetic skipped) is clamped to [0, 1] after its
mapping (``eyeBlink*.gain=1.2`` reads 1.0 at full closure); an overshoot is asked for:
``clamp=0,1.2``, or ``clamp=none`` (written ``"clamp": false``). Rules are (pattern, key,
value), key in ``MAP_KEYS``; a pattern is a channel name in any spelling ``channels``
accepts (``EyeBlink_L``), a glob (``mouth*Left``) or a group (``eyes``: ``channels.GROUPS``),
any case. Later rules win: ``a.merged(b)`` is b on a.

The file format (what ``faceclean calibrate`` writes and ``--calibration`` reads)::

    {"format": "faceclean-adjust/1",
     "channels": {"eyeBlink*": {"gain": 1.2},
                  "jawOpen": {"offset": 0.04, "gain": 1.6, "curve": 1.0, "clamp": [0, 1]},
                  "tongueOut": {"off": true}},
     "calibration": {...facts, optional, shown by describe()},
     "adaptation": {...}}   # optional: a per-face correction AFTER the cleaner

"channels" maps a pattern to its keys, in order (later entries win). "adaptation" (by
``calibrate --guided --tracker mediapipe``, ``faceclean.adaptation``'s) corrects the
cleaner's output, not a level; ``Adjusted`` and ``Adjust.adapt`` apply it.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from typing import Any

import numpy as np

from faceclean.channels import ARKIT52, GROUPS, TRACKERS, canonical, channel_key
from faceclean.errors import FacecleanError
from faceclean.filters.base import MAX_ABS, Stepper

MAP_KEYS: tuple[str, ...] = ("gain", "offset", "curve", "clamp", "off")
FORMAT = "faceclean-adjust/1"
MAX_LEVEL = 1e3  # |gain|, |offset| at most this (weights live in [0, 1])
MAX_CURVE = 100.0  # curve exponent in (0, MAX_CURVE]
RANGE = (0.0, 1.0)  # ARKit's range: the clamp of every channel a rule touches, unless set
FAR = 1.5  # a take whose values' 99th percentile is beyond this is not in [0, 1] at all
NO_CLAMP = (-math.inf, math.inf)  # clamp=none
Rule = tuple[str, str, Any]  # (pattern, key, value), value already validated


@dataclass(frozen=True)
class Levels:
    """The mapping resolved for M columns: arrays (M,), and which columns it touches."""

    gain: np.ndarray
    offset: np.ndarray
    curve: np.ndarray
    lo: np.ndarray  # -inf where unclamped
    hi: np.ndarray  # +inf where unclamped
    off: np.ndarray  # bool
    active: np.ndarray  # (K,) int: columns whose mapping is not the identity


@dataclass(frozen=True)
class Adjust:
    """A per-channel level mapping (see the module docstring). Immutable; build a new one."""

    rules: tuple[Rule, ...] = ()
    facts: dict[str, Any] = field(default_factory=dict)  # calibration facts, for describe()
    scale: float = 1.0  # every value times this first (--scale; not part of the file)
    adaptation: Any = None  # faceclean.adaptation.Adaptation: after the cleaner, or None

    # -- building ---------------------------------------------------------------------------
    @classmethod
    def from_overrides(
        cls, items: Iterable[tuple[str, str, object]], names: Sequence[str] = ARKIT52
    ) -> Adjust:
        """Rules from (pattern, key, value) items, e.g. ``("eyeBlink*", "gain", 1.2)``.

        A pattern must name at least one channel of ``names`` or of ARKit-52; ``off`` with
        value None means on (``tongueOut.off`` given without a value).
        """
        known = tuple(names) + tuple(n for n in ARKIT52 if n not in names)
        rules = []
        for pattern, key, value in items:
            where = f"{pattern}.{key}"
            if key not in MAP_KEYS:
                raise FacecleanError(f"{where}: unknown level key {key!r}; valid: "
                                     f"{', '.join(MAP_KEYS)}")  # fmt: skip
            if not any(matches(pattern, n) for n in known):
                raise FacecleanError(f"{where}: {pattern!r} names no channel (a channel name, "
                                     f"a glob such as 'eyeBlink*', or a group: "
                                     f"{', '.join(GROUPS)})")  # fmt: skip
            rules.append((str(pattern), key, _checked(key, value, where)))
        return cls(tuple(rules))

    @classmethod
    def from_dict(cls, data: Any, label: str = "adjust") -> Adjust:
        """From the JSON document of the module docstring."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise FacecleanError(f"{label}: not a faceclean level file (format {FORMAT!r})")
        chans = data.get("channels", {})
        if not isinstance(chans, dict) or not all(isinstance(v, dict) for v in chans.values()):
            raise FacecleanError(f"{label}: 'channels' must map patterns to {{key: value}}")
        items = [(p, k, v) for p, keys in chans.items() for k, v in keys.items()]
        try:
            for pattern, key, value in items:
                _json_typed(key, value, f"{pattern}.{key}")
            rules = cls.from_overrides(items).rules
        except FacecleanError as e:
            raise FacecleanError(f"{label}: {e}") from None
        adaptation = None
        if data.get("adaptation") is not None:
            from faceclean.adaptation import Adaptation

            adaptation = Adaptation.from_dict(data["adaptation"], label)
        facts = _facts(data.get("calibration", {}), label)
        said = (facts.get("tracker"), getattr(adaptation, "tracker", None))
        if None not in said and said[0] != said[1]:
            raise FacecleanError(f"{label}: made for tracker {said[0]}, adapted for {said[1]}")
        return cls(rules, facts, adaptation=adaptation)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Adjust:
        """A level file (``--calibration``): through the bounded reader, strict JSON."""
        from faceclean.io.source import read_json

        return cls.from_dict(read_json(path, "calibration file"), str(path))

    def to_dict(self) -> dict[str, Any]:
        """The JSON document. Keys of one pattern are written together, in the order the
        patterns first appear; a key set twice for one pattern keeps its last value."""
        chans: dict[str, dict[str, Any]] = {}
        for pattern, key, value in self.rules:
            if key == "clamp":
                value = False if value == NO_CLAMP else list(value)
            chans.setdefault(pattern, {})[key] = value
        out: dict[str, Any] = {"format": FORMAT, "channels": chans}
        if self.facts:
            out["calibration"] = self.facts
        if self.adaptation is not None:
            out["adaptation"] = self.adaptation.to_dict()
        return out

    def save(self, path: str | os.PathLike) -> None:
        from faceclean.io.atomic import atomic_write

        atomic_write(path, json.dumps(self.to_dict(), indent=1) + "\n")

    def merged(self, other: Adjust) -> Adjust:
        """This mapping with ``other``'s rules on top (other wins where both set a key)."""
        scale = other.scale if other.scale != 1.0 else self.scale
        after = other.adaptation if other.adaptation is not None else self.adaptation
        return Adjust(self.rules + other.rules, {**self.facts, **other.facts}, scale, after)

    def scaled(self, scale: float) -> Adjust:
        """This mapping after every value is multiplied by ``scale`` (``--scale``)."""
        if not math.isfinite(scale) or scale <= 0:
            raise FacecleanError(f"--scale must be a finite number > 0 (got {scale:g})")
        return Adjust(self.rules, self.facts, float(scale), self.adaptation)

    # -- using ------------------------------------------------------------------------------
    @property
    def is_identity(self) -> bool:
        return not self.rules and self.scale == 1.0 and self.adaptation is None

    def adapt(self, values: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """The cleaner's output ``values`` (N, M) with the adaptation applied (a copy)."""
        if self.adaptation is None:
            return np.array(values, dtype=np.float64)
        return self.adaptation.apply(values, names)

    def levels(self, names: Sequence[str]) -> Levels:
        """The mapping for columns ``names`` (M,)."""
        m = len(names)
        gain, offset, curve = np.ones(m), np.zeros(m), np.ones(m)
        lo, hi, off = np.full(m, -np.inf), np.full(m, np.inf), np.zeros(m, bool)
        touched, clamped = np.zeros(m, bool), np.zeros(m, bool)
        for pattern, key, value in self.rules:
            cols = [j for j, n in enumerate(names) if matches(pattern, n)]
            touched[cols] = True
            clamped[cols] |= key == "clamp"
            if key == "gain":
                gain[cols] = value
            elif key == "offset":
                offset[cols] = value
            elif key == "curve":
                curve[cols] = value
            elif key == "clamp":
                lo[cols], hi[cols] = value
            else:
                off[cols] = value
        if self.scale != 1.0:  # blendshape columns only (never a head angle's degrees)
            arkit = np.array([canonical(n) is not None for n in names], dtype=bool)
            touched |= arkit
            gain[arkit] *= self.scale  # gain (s x - offset) = gain s (x - offset / s)
            offset[arkit] /= self.scale
        moves = (gain != 1.0) | (offset != 0.0) | (curve != 1.0)
        default = touched & moves & ~clamped  # a level step, no clamp asked: ARKit's range
        lo[default], hi[default] = RANGE
        ident = ~moves & np.isneginf(lo) & np.isposinf(hi)
        active = np.flatnonzero(~ident | off)
        return Levels(gain, offset, curve, lo, hi, off, active)

    def apply(self, values: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """Mapped values, same shape as ``values`` ((N, M) or (M,)); NaN stays NaN."""
        x = np.asarray(values, dtype=np.float64)
        if self.is_identity:
            return x.copy()
        return apply_levels(self.levels(names), x)

    def describe(self, names: Sequence[str] | None = None) -> list[str]:
        """Lines for ``info`` and the report: one per pattern, then calibration facts."""
        lines = []
        for pattern, keys in self.to_dict()["channels"].items():
            shown = [] if names is None else [n for n in names if matches(pattern, n)]
            plural = "s" if len(shown) != 1 else ""
            where = f" ({len(shown)} channel{plural})" if names is not None else ""
            lines.append(f"{pattern}{where}: " + ", ".join(_show(k, v) for k, v in keys.items()))
        facts = self.facts
        guided = facts.get("guided")
        if isinstance(guided, dict):  # calibrate --guided
            seen, missed = guided.get("seen", []), guided.get("not_seen", [])
            lines.append(
                f"guided calibration from {facts.get('take', 'a take')} (tracker "
                f"{facts.get('tracker', '?')}): {len(seen)} of {len(seen) + len(missed)} "
                "prompts seen" + (f"; not seen: {', '.join(missed)}" if missed else "")
            )
        elif facts:
            levels = (  # "none": calibrate --tracker mediapipe, the map reads the rest itself
                "no levels (the cleaner reads the face's rest)" if facts.get("levels") == "none"
                else f"{len(facts.get('moved', []))} channels moved, {len(facts.get('lifted', []))}"
                f" lifted to their top, {len(facts.get('closed', []))} eyelids scaled to close "
                "(their blinks)"
            )  # fmt: skip
            lines.append(f"calibrated from {facts.get('take', 'a take')}: "
                         f"{facts.get('frames', '?')} frames, neutral "
                         f"{facts.get('neutral_s', '?')} s; {levels}")  # fmt: skip
        if self.adaptation is not None:
            lines.append(self.adaptation.summary())
        return lines or ["identity (no level mapping)"]


def check_range(values: np.ndarray, names: Sequence[str], where: str,
                scale: float | None = None) -> None:  # fmt: skip
    """FacecleanError (one line, with the fix) when ``values`` (N, M) of ARKit-named columns
    are far outside [0, 1]: their 99th percentile of |value| beyond FAR (a take in percent),
    or most past MAX_ABS (fewer: glitches); with the user's ``--scale``, the latter scaled."""
    cols = [j for j, n in enumerate(names) if canonical(n) is not None]
    x = np.abs(np.asarray(values, dtype=np.float64))
    x = x if len(cols) == x.shape[-1] else x[..., cols]  # (every column ARKit's: no copy)
    x = x if scale is None else x * abs(scale)
    # The 99th percentile of the n values within MAX_ABS lies between the sorted values at
    # floor(p) and ceil(p), p = 0.99 (n - 1): when ceil(p)'s is within FAR, so is it.
    n, huge = np.count_nonzero(x <= MAX_ABS), np.count_nonzero(np.isfinite(x) & (x > MAX_ABS))
    if huge > n:  # the take itself, a unit a million times off
        top = float(np.max(x, where=np.isfinite(x), initial=0.0))
        fix = 10.0 ** -math.ceil(math.log10(top)) * abs(scale or 1.0)  # the user's, further
        said = "" if scale is None else f" with --scale {scale:g}"
        raise FacecleanError(f"{where}: blendshape values reach {top:.3g}{said} in {huge} "
                             f"cells: {'use' if said else 'add'} --scale {fix:g}")  # fmt: skip
    far = np.count_nonzero((x > FAR) & (x <= MAX_ABS))
    if scale is not None or not n or math.ceil(0.99 * (n - 1)) < n - far:
        return
    high = float(np.percentile(x[x <= MAX_ABS], 99))
    if high > FAR:
        guess = 0.01 if high <= 100.0 * FAR else 10.0 ** -math.ceil(math.log10(high))
        raise FacecleanError(f"{where}: blendshape values reach {high:.3g} (99th percentile), "
                             f"far outside ARKit's [0, 1] (percentages?): add --scale {guess:g}, "
                             "or --scale 1 to clean them as they are")  # fmt: skip


def is_level_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a JSON file in this module's format (looks at its start only;
    False for anything but a regular file, which its reader then refuses)."""
    from faceclean.io import source

    if not str(path).lower().endswith(".json") or not os.path.isfile(path):
        return False
    try:
        with source.open_binary(path) as f:
            head = f.read(4096)
    except (FacecleanError, OSError):
        return False
    return FORMAT.encode() in head


def apply_levels(lv: Levels, x: np.ndarray) -> np.ndarray:
    """The module equation on (N, M) or (M,) values for resolved levels."""
    out = x.copy()
    a = lv.active
    if not len(a):
        return out
    with np.errstate(over="ignore", invalid="ignore"):  # a glitch value may overflow to inf
        u = lv.gain[a] * (x[..., a] - lv.offset[a])
        u = np.sign(u) * np.abs(u) ** lv.curve[a]
        u = np.clip(u, lv.lo[a], lv.hi[a])
    u = np.where(lv.off[a] & ~np.isnan(u), 0.0, u)
    out[..., a] = u
    return out


def matches(pattern: str, name: str) -> bool:
    """Does ``pattern`` (name, glob or group, case-insensitive) name channel ``name``?"""
    c = channel_key(name)
    p = pattern.strip()
    if p.lower() in GROUPS:
        return c in GROUPS[p.lower()]
    if any(ch in p for ch in "*?["):
        return fnmatchcase(c.lower(), p.lower())
    return channel_key(p).lower() == c.lower()


def _json_number(v: object) -> bool:
    """A JSON number (true and false are not numbers, though Python says they are)."""
    return isinstance(v, int | float) and not isinstance(v, bool)


def _json_typed(key: str, value: object, where: str) -> None:
    """A level file's value is of its JSON type (``--set`` takes text; a file does not:
    ``"gain": "2"`` is a mistake to name, not a number to guess)."""
    number = _json_number
    if key == "off":
        ok, want = value is None or isinstance(value, bool), "true or false"
    elif key == "clamp":
        pair = isinstance(value, list) and len(value) == 2 and all(number(v) for v in value)
        none = value is None or value is False or value in ("none", "off")  # as --set spells it
        ok, want = none or pair, "[LO, HI] or false (no clamp)"
    else:
        ok, want = number(value), "a number"
    if not ok:
        raise FacecleanError(f"{where}: expected {want}, got {json.dumps(value)[:80]}")


def _checked(key: str, value: object, where: str) -> Any:
    """A validated value for ``key``: floats, a (lo, hi) pair, or a bool."""
    if key == "off":
        if value is None or value is True or value is False:
            return value is not False
        text = str(value).strip().lower()
        if text in ("true", "1", "yes", "on"):
            return True
        if text in ("false", "0", "no"):
            return False
        raise FacecleanError(f"{where}: expected true or false, got {value!r}")
    if key == "clamp":
        if value is False or value is None or str(value).strip().lower() in ("none", "off"):
            return NO_CLAMP  # clamp=none: a calibrated overshoot, unbounded
        pair = value
        if isinstance(value, str):
            pair = value.replace("[", "").replace("]", "").split(",")
        try:
            lo, hi = (float(v) for v in pair)  # type: ignore[union-attr]
        except (TypeError, ValueError):
            raise FacecleanError(f"{where}: expected two numbers LO,HI, got {value!r}") from None
        if math.isnan(lo) or math.isnan(hi) or lo > hi:
            raise FacecleanError(f"{where}: expected LO <= HI, got {value!r}")
        return (lo, hi)
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise FacecleanError(f"{where}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(number):
        raise FacecleanError(f"{where}: expected a finite number, got {value!r}")
    if key == "curve" and not 0 < number <= MAX_CURVE:
        raise FacecleanError(f"{where}: the curve exponent must be in (0, {MAX_CURVE:g}]")
    if key in ("gain", "offset") and abs(number) > MAX_LEVEL:
        raise FacecleanError(f"{where}: must be within +-{MAX_LEVEL:g} (weights are 0..1)")
    return number


def _facts(facts: Any, label: str) -> dict[str, Any]:
    """A level file's calibration facts (what ``calibrate`` measured, shown by ``info``),
    each of its documented type; FacecleanError naming the first that is not. Other keys
    are kept as they are (nothing reads them)."""
    if not isinstance(facts, dict):
        raise FacecleanError(f"{label}: 'calibration' must be an object of facts")

    def number(v: Any) -> bool:
        return _json_number(v) and math.isfinite(v)

    def names(v: Any) -> bool:
        return isinstance(v, list) and all(isinstance(n, str) for n in v)

    def channels(v: Any) -> bool:
        return isinstance(v, dict) and all(
            isinstance(c, dict) and all(x is None or number(x) for x in c.values())
            for c in v.values()
        )

    kinds = {
        "take": (lambda v: isinstance(v, str), "a file name"),
        "frames": (lambda v: number(v) and v >= 0, "a frame count"),
        "neutral_s": (lambda v: number(v) and v >= 0, "seconds"),
        "tracker": (lambda v: v is None or v in TRACKERS, f"one of {', '.join(TRACKERS)}"),
        "rom": (lambda v: isinstance(v, bool), "true or false"),
        "moved": (names, "a list of channel names"),
        "lifted": (names, "a list of channel names"),
        "closed": (names, "a list of channel names"),
        "channels": (channels, "channel -> {neutral, top, noise, gain: numbers}"),
        "hold": (lambda v: isinstance(v, list) and len(v) == 2 and all(map(number, v)),
                 "[start, end] seconds"),
        "guided": (lambda v: isinstance(v, dict) and all(names(v.get(k, []))
                                                         for k in ("seen", "not_seen", "placed")),
                   "{seen, not_seen, placed: lists of prompt ids, ...}"),
    }  # fmt: skip
    for key, (ok, what) in kinds.items():
        if key in facts and not ok(facts[key]):
            raise FacecleanError(f"{label}: calibration fact {key!r} must be {what}")
    return facts


def _show(key: str, value: Any) -> str:
    if key == "off":
        return "off" if value else "on"
    if key == "clamp":  # a rule's (lo, hi), or the file's false for no clamp
        if value is False or tuple(value) == NO_CLAMP:
            return "no clamp"
        return f"clamp [{value[0]:g}, {value[1]:g}]"
    return f"{key} {value:.4g}"


class Adjusted(Stepper):
    """A stream cleaner whose input goes through a level mapping first (fixed columns),
    and whose output through the mapping's adaptation, if it has one."""

    def __init__(self, inner: Any, adjust: Adjust, names: Sequence[str]) -> None:
        self.inner, self.adjust, self.names = inner, adjust, tuple(names)
        self.name = getattr(inner, "name", "cleaner")
        self._levels = adjust.levels(self.names)
        from faceclean.adaptation import after

        self._after = after(inner, adjust.adaptation, self.names)  # None without one
        self.reset()

    def reset(self) -> None:
        self.inner.reset()

    def step(self, frame: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        x = np.asarray(frame, dtype=np.float64)
        y = self.inner.step(apply_levels(self._levels, x), t)
        return y if self._after is None else self._after(y)
