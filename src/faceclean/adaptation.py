"""A per-face adaptation: a linear correction applied AFTER the cleaner (guided calibration).

Where ``faceclean.adjust``'s levels map the raw values before the cleaner, the adaptation
corrects the cleaner's output y (ARKit weights) for one face::

    y' = clip(y + c + D y, 0, 1)        c (M,) offsets, D (M, M) sparse, W = I + D

D is nonzero only within a channel group (``channels.GROUPS``: the tracker mixes channels
of one region, e.g. MediaPipe's eye squint and blink), and is fitted shrunk toward 0, that
is W toward the identity: the shipped cleaner alone (``faceclean.guided.fit``). Columns it
does not name pass through bit for bit; a missing frame (NaN) stays missing.

It is a separate section of the calibration file (``faceclean-adjust/1``), which readers
older than it ignore::

    "adaptation": {"format": "faceclean-adaptation/1", "tracker": "mediapipe",
                   "cleaner": "tracker-map (mediapipe.npz ...)",   # what it was fitted after
                   "offset": {"jawOpen": -0.03, ...},
                   "matrix": {"eyeBlinkLeft": {"eyeBlinkLeft": 0.21, "eyeSquintLeft": -0.1}, ...}}

``matrix[out][in]`` is D's entry (the change from the identity). A guided calibration of
MediaPipe also carries the face's own resting reading of the mouth's inputs, and the
outputs that measure their rise from it (learned/tracker_map.py ``set_rest_reading``; the
cleaner takes it: ``attach``)::

    "rest": {"reading": {"mouthSmileLeft": 0.03, ...}, "outputs": ["mouthSmileLeft", ...]}

and may close the face's blinks: where the script's closed eyes read ``top`` after the
correction (short of shut), a channel is lifted from ``knee`` (between its rest and top)
so that its own top reads 1, after D::

    "closure": {"eyeBlinkLeft": {"knee": 0.31, "top": 0.62}, ...}
    z' = max(z, clip((z - knee) / (top - knee), 0, 1))

and may name outputs the map reads as their own input's rise alone, where its other rows
misread this face (learned/tracker_map.py ``set_own_rise``; ``attach`` hands them over)::

    "own": ["browDownLeft", "browDownRight", "browInnerUp", ...]
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from faceclean.channels import ARKIT52, TRACKERS, canonical
from faceclean.errors import FacecleanError

FORMAT = "faceclean-adaptation/1"
MAX_OFFSET = 0.5  # weight units
MAX_COEF = 3.0  # |D| entries
MIN_SPAN = 0.02  # weight units: a closure's top over its knee (a smaller span is a step)


@dataclass(frozen=True)
class Adaptation:
    """The correction of the module docstring; ``apply`` on (N, M) or (M,) values."""

    offset: dict[str, float]
    matrix: dict[str, dict[str, float]]
    tracker: str | None = None
    facts: dict[str, Any] = field(default_factory=dict)  # other keys, kept as they are
    rest: dict[str, float] = field(default_factory=dict)  # input -> the face's reading at rest
    rest_outputs: tuple[str, ...] = ()  # the outputs that measure a rise from ``rest``
    closure: dict[str, tuple[float, float]] = field(default_factory=dict)  # name -> knee, top
    own: tuple[str, ...] = ()  # outputs the map reads as their own rise alone

    @classmethod
    def from_dict(cls, data: Any, label: str = "adaptation") -> Adaptation:
        where = f"{label}: adaptation"
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise FacecleanError(f"{where}: not of format {FORMAT!r}")
        offset = data.get("offset", {})
        matrix = data.get("matrix", {})
        if not isinstance(offset, dict) or not isinstance(matrix, dict):
            raise FacecleanError(f"{where}: offset and matrix must be objects")
        if not all(isinstance(row, dict) for row in matrix.values()):
            raise FacecleanError(f"{where}: matrix must map a channel to {{channel: number}}")
        names = [*offset, *matrix, *(n for row in matrix.values() for n in row)]
        bad = [n for n in names if canonical(n) != n]
        if bad:
            raise FacecleanError(f"{where}: {bad[0]!r} is not an ARKit channel name")
        for n, v in offset.items():
            _bounded(v, MAX_OFFSET, f"{where} offset {n}")
        for o, row in matrix.items():
            for i, v in row.items():
                _bounded(v, MAX_COEF, f"{where} matrix {o}.{i}")
        tracker = data.get("tracker")
        if tracker is not None and (not isinstance(tracker, str) or tracker not in TRACKERS):
            raise FacecleanError(f"{where}: tracker must be one of {', '.join(TRACKERS)}, not "
                                 f"{tracker!r}")  # fmt: skip
        if not isinstance(data.get("cleaner", ""), str):
            raise FacecleanError(f"{where}: cleaner must be the name of the cleaner it follows")
        keys = ("format", "offset", "matrix", "tracker", "rest", "closure", "own")
        others = {k: v for k, v in data.items() if k not in keys}
        offset = {n: float(v) for n, v in offset.items()}
        matrix = {o: {i: float(v) for i, v in row.items()} for o, row in matrix.items()}
        reading, outputs = _rest(data.get("rest"), where)
        closure = _closure(data.get("closure", {}), where)
        own = data.get("own", [])
        if not isinstance(own, list):
            raise FacecleanError(f"{where}: own must be a list of ARKit channel names")
        bad = [n for n in own if not isinstance(n, str) or canonical(n) != n]
        if bad:
            raise FacecleanError(f"{where}: own: {bad[0]!r} is not an ARKit channel name")
        return cls(offset, matrix, tracker, others, reading, outputs, closure, tuple(own))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"format": FORMAT, "tracker": self.tracker, **self.facts}
        out["offset"] = {n: round(v, 6) for n, v in self.offset.items()}
        out["matrix"] = {
            o: {i: round(v, 6) for i, v in row.items()} for o, row in self.matrix.items()
        }
        if self.rest:
            reading = {n: round(v, 6) for n, v in self.rest.items()}
            out["rest"] = {"reading": reading, "outputs": list(self.rest_outputs)}
        if self.closure:
            out["closure"] = {n: {"knee": round(k, 6), "top": round(t, 6)}
                              for n, (k, t) in self.closure.items()}  # fmt: skip
        if self.own:
            out["own"] = list(self.own)
        return out

    @property
    def channels(self) -> tuple[str, ...]:
        """The output channels it changes, in ARKit order."""
        touched = (
            {n for n, v in self.offset.items() if v}
            | set(self.closure)
            | {o for o, row in self.matrix.items() if any(row.values())}
        )
        return tuple(n for n in ARKIT52 if n in touched)

    def summary(self) -> str:
        """One line of what it holds (``faceclean info``)."""
        cross = sum(1 for o, row in self.matrix.items() for i in row if i != o)
        parts = [
            f"adaptation after the cleaner ({self.facts.get('cleaner', '?')}): "
            f"{len(self.channels)} channels corrected, {cross} cross-channel terms"
        ]
        for n, what in ((len(self.rest), "channels in the face's rest reading"),
                        (len(self.closure), "blinks lifted to its closure"),
                        (len(self.own), "channels read as their own rise")):  # fmt: skip
            parts += [f"{n} {what}"] if n else []
        return "; ".join(parts)

    def operator(self, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(cols (K,) the columns it writes, c (K,), D (K, M)) for columns ``names``."""
        col = {n: j for j, n in enumerate(names)}
        cols = np.array([col[n] for n in self.channels if n in col], dtype=np.intp)
        c = np.array([self.offset.get(names[j], 0.0) for j in cols])
        d = np.zeros((len(cols), len(names)))
        for k, j in enumerate(cols):
            for i, v in self.matrix.get(names[j], {}).items():
                if i in col:
                    d[k, col[i]] = v
        return cols, c, d

    def apply(self, values: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """Corrected values, same shape as ``values``; NaN rows stay NaN."""
        return Applier(self, names)(values)


class Applier:
    """An adaptation resolved for fixed columns (the streaming path's per-frame cost)."""

    def __init__(self, adaptation: Adaptation, names: Sequence[str]) -> None:
        self.cols, self.c, self.d = adaptation.operator(tuple(names))
        shut = [(k, *adaptation.closure[names[j]]) for k, j in enumerate(self.cols)
                if names[j] in adaptation.closure]  # fmt: skip
        self.shut = np.array([k for k, _, _ in shut], dtype=np.intp)  # (L,) of the K columns
        self.knee = np.array([kn for _, kn, _ in shut])  # (L,)
        self.span = np.array([top - kn for _, kn, top in shut])  # (L,) > 0

    def __call__(self, values: np.ndarray) -> np.ndarray:
        y = np.array(values, dtype=np.float64)
        if not len(self.cols):
            return y
        with np.errstate(invalid="ignore"):
            z = y[..., self.cols] + self.c + np.nan_to_num(y) @ self.d.T  # (..., K)
            if len(self.shut):  # the closure: max(z, (z - knee) / (top - knee))
                q = z[..., self.shut]
                z[..., self.shut] = np.maximum(q, (q - self.knee) / self.span)
            z = np.where(np.isnan(y[..., self.cols]), np.nan, np.clip(z, 0.0, 1.0))
        y[..., self.cols] = z
        return y


def after(cleaner: Any, adaptation: Adaptation | None, names: Sequence[str]) -> Applier | None:
    """A stream wrapper's correction after ``cleaner`` for columns ``names`` (None without
    an adaptation), its rest reading handed to ``cleaner`` (``attach``)."""
    if adaptation is None:
        return None
    attach(cleaner, adaptation)
    return Applier(adaptation, names)


def attach(cleaner: Any, adaptation: Adaptation | None) -> None:
    """Hands ``adaptation``'s rest reading and own-rise outputs to ``cleaner`` where both
    have them (the tracker map takes them: ``set_rest_reading``, ``set_own_rise``); any
    other cleaner keeps the stream's own rest and its rows, and the correction after it
    applies as before."""
    if adaptation is None:
        return
    own = getattr(cleaner, "set_own_rise", None)
    if own is not None:  # (): the map's own rows again, after another face's
        own(adaptation.own)
    take = getattr(cleaner, "set_rest_reading", None)
    if adaptation.rest and take is not None:
        take(adaptation.rest, adaptation.rest_outputs)


def clean_calibrated(cleaner: Any, anim: Any, adjust: Any, run: Any = None,
                     correct: bool = True) -> Any:  # fmt: skip
    """``anim`` (an Animation) cleaned as ``clean --calibration`` cleans it: ``adjust``'s
    levels on the values (none: the take itself, not a copy), its adaptation's rest reading
    handed to ``cleaner`` (``attach``), the cleaner run (``run(mapped)``; its ``clean`` by
    default), and, if ``correct``, the adaptation's correction after it."""
    mapped = anim if adjust.is_identity else anim.with_values(adjust.apply(anim.values, anim.names))
    attach(cleaner, adjust.adaptation)
    cleaned = (run or cleaner.clean)(mapped)
    if adjust.adaptation is None or not correct:
        return cleaned
    return cleaned.with_values(adjust.adaptation.apply(cleaned.values, cleaned.names))


def fitted_after(words: str | None) -> str | None:
    """The label of a cleaner an adaptation corrects, as the file records it (``cleaner``): a
    model file's name and the first 12 hex digits of its sha256; None where ``words`` name
    no file (a method, a preset, the default)."""
    path = Path(words) if words else None
    if path is None or not path.is_file():
        return None
    return f"{path.name} sha256:{hashlib.sha256(path.read_bytes()).hexdigest()[:12]}"


def check_cleaner(adaptation: Adaptation | None, words: str | None, where: str) -> None:
    """Refuses an adaptation whose correction (offset, matrix, closure: of one cleaner's
    output) was fitted after another cleaner than ``words`` name (a retrained model, another
    method). A rest reading or own-rise list alone is the map's input, kept (``unread`` says
    where nothing reads it); a file that records no model's sha256 is taken as it is."""
    if adaptation is None or not (adaptation.offset or adaptation.matrix or adaptation.closure):
        return
    want = adaptation.facts.get("cleaner")
    if not isinstance(want, str) or " sha256:" not in want:
        return
    have = fitted_after(words)
    if have != want:
        raise FacecleanError(
            f"{where}: its correction was fitted after {want}, and this command cleans with "
            f"{have or words or 'the default cleaner'}: calibrate again with that cleaner"
        )


def check_tracker(adjust: Any, tracker: str | None, where: str) -> None:
    """Refuses a calibration (``adjust``) made for another tracker than ``tracker``: its
    adaptation's, else its levels' recorded one (a file from before either was recorded
    is taken as it is)."""
    made_for = getattr(adjust.adaptation, "tracker", None) or adjust.facts.get("tracker")
    if made_for is not None and tracker is not None and tracker != made_for:
        raise FacecleanError(
            f"{where}: a calibration for tracker {made_for}, not {tracker}: give --tracker "
            f"{made_for}, or calibrate again with --tracker {tracker}"
        )


def unread(adjust: Any, cleaner: Any) -> str:
    """What a calibration (``adjust``) that holds nothing but a rest reading would change
    for ``cleaner`` when the cleaner reads none: "" where it changes something, else why
    it changes nothing (a one-line note for the command to print)."""
    ad = adjust.adaptation
    if (ad is None or not (ad.rest or ad.own) or ad.matrix or ad.offset or adjust.rules
            or ad.closure or getattr(cleaner, "set_rest_reading", None) is not None):  # fmt: skip
        return ""
    what = "a rest reading" if ad.rest else "channels read as their own rise"
    return f"is {what} for the MediaPipe map and changes nothing here"


def _rest(data: Any, where: str) -> tuple[dict[str, float], tuple[str, ...]]:
    """The "rest" section checked: (reading, outputs); none: ({}, ())."""
    if data is None:
        return {}, ()
    reading, outputs = (data.get(k) if isinstance(data, dict) else None
                        for k in ("reading", "outputs"))  # fmt: skip
    if not isinstance(reading, dict) or not isinstance(outputs, list):
        raise FacecleanError(f"{where}: rest must be {{\"reading\": {{channel: number}}, "
                             "\"outputs\": [channel, ...]}")  # fmt: skip
    bad = [n for n in [*reading, *outputs] if not isinstance(n, str) or canonical(n) != n]
    if bad:
        raise FacecleanError(f"{where}: rest: {bad[0]!r} is not an ARKit channel name")
    for n, v in reading.items():
        _bounded(v, 1.0, f"{where} rest reading {n}")
        if v < 0:
            raise FacecleanError(f"{where} rest reading {n}: must be within [0, 1]")
    return {n: float(v) for n, v in reading.items()}, tuple(outputs)


def _closure(data: Any, where: str) -> dict[str, tuple[float, float]]:
    """The "closure" section checked: {channel: (knee, top)}, 0 <= knee < top <= 1."""
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise FacecleanError(f"{where}: closure must be {{channel: {{\"knee\": number, "
                             "\"top\": number}}}")  # fmt: skip
    out = {}
    for n, v in data.items():
        if canonical(n) != n:
            raise FacecleanError(f"{where}: closure: {n!r} is not an ARKit channel name")
        knee, top = v.get("knee"), v.get("top")
        _bounded(knee, 1.0, f"{where} closure {n} knee")
        _bounded(top, 1.0, f"{where} closure {n} top")
        if not 0 <= knee < top - MIN_SPAN:
            raise FacecleanError(f"{where} closure {n}: needs 0 <= knee < top - {MIN_SPAN:g}")
        out[n] = (float(knee), float(top))
    return out


def _bounded(v: Any, limit: float, where: str) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise FacecleanError(f"{where}: expected a finite number, got {v!r}")
    if abs(v) > limit:
        raise FacecleanError(f"{where}: must be within +-{limit:g}")
