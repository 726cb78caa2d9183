"""What the tuning page has chosen, in the CLI's own words, and the files it writes.

A ``Tuning`` is the command line the page stands for: the cleaner's words (``--method``,
``--model`` or ``--preset``: one text, ``faceclean.resolve``'s), the ``--set`` items
(``KEY=VALUE``, ``PATTERN.KEY=VALUE``, levels ``PATTERN.gain=...``) and a calibration
(``--calibration``'s level mapping). ``with_choice`` checks them through the resolver
and refuses them with its one-line reasons, so a value the CLI would refuse never
reaches a cleaner. ``build(names)`` makes the cleaner as ``clean`` and ``relay`` do:
the levels (calibration, then the level items on top) before ``Choice.build``.

Files are the formats the CLI reads: ``save_preset`` a ``faceclean-preset/1``
(``--preset``: a classical method, its params and per-group values; per-channel items
that a preset cannot hold are returned as ``--set`` words), ``save_levels`` a
``faceclean-adjust/1`` (``--calibration``: the calibration with the level items on top).
``command()`` is the line that reproduces the page in a shell.
"""

from __future__ import annotations

import copy
import inspect
import os
import shlex
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from faceclean import filters
from faceclean.adaptation import clean_calibrated
from faceclean.adjust import MAP_KEYS, Adjust, Adjusted, apply_levels
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, GROUPS
from faceclean.errors import FacecleanError
from faceclean.filters import presets
from faceclean.resolve import Choice, parse_item, resolve, tracker_words

MAX_ITEMS = 256  # --set items one page state may hold
MAX_TEXT = 400  # characters of one word or item


@dataclass(frozen=True)
class Tuning:
    """The page's command line; immutable (a change is a new Tuning, checked first)."""

    words: str | None = None  # --method/--model/--preset (None: the shipped default)
    items: tuple[str, ...] = ()  # --set items, in order (later ones win)
    calibration: Adjust | None = None  # --calibration's mapping (or a Calibrate press)
    calibration_file: str | None = None  # where it was loaded from or saved to
    tracker: str | None = None  # --tracker: its shipped cleaner when no words are given
    choice: Choice = field(default=None, repr=False, compare=False)  # type: ignore[assignment]

    def with_choice(self) -> Tuning:
        """This tuning with its ``Choice`` resolved; FacecleanError for bad words or items."""
        words = self.words if self.words not in ("", None) else None
        for text in (words or "", *self.items):
            if len(text) > MAX_TEXT:
                raise FacecleanError(f"a setting of {len(text)} characters (at most {MAX_TEXT})")
        if len(self.items) > MAX_ITEMS:
            raise FacecleanError(f"{len(self.items)} settings (at most {MAX_ITEMS})")
        tracker = self.tracker if self.tracker not in ("", None) else None
        chosen = words if words is not None else tracker_words(tracker)  # options.words' rule
        choice = resolve(chosen, list(self.items))
        choice.adjust(ARKIT52)  # bad level values fail now, with the CLI's reason
        return replace(self, words=words, tracker=tracker, choice=choice)

    def changed(
        self, words: str | None, items: Sequence[str], tracker: str | None = None
    ) -> Tuning:
        """A checked tuning with other words, items and tracker (the calibration kept)."""
        items = tuple(str(i) for i in items)
        return replace(self, words=words, items=items, tracker=tracker).with_choice()

    def calibrated(self, adjust: Adjust | None, path: str | None = None) -> Tuning:
        return replace(self, calibration=adjust, calibration_file=path)

    def neutral(
        self, anim: Animation, seconds: float, take: str, tops: dict[str, float] | None = None
    ) -> Adjust:
        """The calibration of a neutral hold (``anim``'s first ``seconds``) for this
        tuning's cleaner, as ``calibrate`` writes it: levels (``tops`` kept), or, for a
        cleaner that reads the face's rest itself (the MediaPipe map), that reading and no
        levels (guided.fit.rest_calibration: levels before the map cost on 7 of 10 faces)."""
        from faceclean.calibration import calibrate

        live = calibrate(anim, seconds, tops=tops, take=take)
        cleaner = self.choice.build(anim.names)
        if getattr(cleaner, "set_rest_reading", None) is None:
            return live
        from faceclean.guided.fit import rest_calibration

        facts = {k: live.facts[k] for k in ("take", "frames", "neutral_s")}
        adjust = rest_calibration(anim, facts["neutral_s"], facts, cleaner)
        if adjust.adaptation is None:
            raise FacecleanError("no mouth or gaze channel to read at rest: nothing calibrated")
        return adjust

    # -- the cleaner, as the CLI builds it -----------------------------------------------
    def levels(self, names: Sequence[str] = ARKIT52) -> Adjust:
        """The level mapping before the cleaner: calibration, then the level items."""
        return (self.calibration or Adjust()).merged(self.choice.adjust(names))

    def build(self, names: Sequence[str] = ARKIT52) -> Any:
        """A fresh stream cleaner for ``names`` behind the level mapping (``relay``'s)."""
        if self.choice.offline:
            raise FacecleanError(
                f"{self.choice.source} is offline (non-causal): it cannot run live"
            )
        cleaner = self.choice.build(names)
        adjust = self.levels(names)
        return cleaner if adjust.is_identity else Adjusted(cleaner, adjust, names)

    def clean(self, anim: Animation) -> Animation:
        """``anim`` cleaned as ``faceclean clean`` does: levels on the values, then the
        cleaner's ``clean``."""
        return clean_calibrated(self.choice.build(anim.names), anim, self.levels(anim.names))

    def map_levels(self, values: np.ndarray, names: Sequence[str]) -> np.ndarray:
        return apply_levels(self.levels(names).levels(names), np.asarray(values, np.float64))

    # -- what the page shows ---------------------------------------------------------------
    def describe(self) -> dict[str, Any]:
        """The state for the page: words, items, the method's own keys with their value
        per channel (ARKit-52 order), the calibration's facts, the command line."""
        method = self.choice.method
        cls = filters.cleaner_class(method)
        per = tuple(getattr(cls, "PER_CHANNEL", ()))
        values: dict[str, list[float | None]] = {}
        if per:
            built = self.choice.build(ARKIT52)
            for key in per:
                v = getattr(built, key, None)
                if v is not None:
                    values[key] = [float(x) for x in np.broadcast_to(v, (len(ARKIT52),))]
        cal = self.calibration
        return {
            "words": self.words,
            "tracker": self.tracker,
            "items": list(self.items),
            "method": method,
            "source": self.choice.source,
            "offline": self.choice.offline,
            "keys": list(per),
            "values": values,
            "calibration": None if cal is None else {"file": self.calibration_file, **cal.facts},
            "command": self.command(),
        }

    def command(self, verb: str = "clean IN -o OUT") -> str:
        """The shell line for this state (the calibration as the file it was saved to)."""
        words = [] if self.words is None else ["--method", self.words]
        words += ["--tracker", self.tracker] if self.tracker and self.words is None else []
        for item in self.items:
            words += ["--set", item]
        if self.calibration is not None:
            words += ["--calibration", self.calibration_file or "CALIBRATION.json"]
        return f"faceclean {verb} " + " ".join(shlex.quote(w) for w in words)

    # -- the files -------------------------------------------------------------------------
    def save_levels(self, path: str | os.PathLike) -> Adjust:
        """The level mapping as a ``--calibration`` file; returns what was written."""
        json_path(path, "levels")
        adjust = self.levels(ARKIT52)
        adjust.save(path)
        return adjust

    def save_preset(self, path: str | os.PathLike) -> list[str]:
        """The cleaner and its smoothing items as a ``--preset`` file; returns the items a
        preset cannot hold (per-channel smoothing, levels), as ``--set`` words."""
        json_path(path, "preset")
        if self.words is None and self.tracker:  # the tracker's own cleaner
            doc, rest = preset_doc(tracker_words(self.tracker), self.items,
                                   f"--tracker {self.tracker}")  # fmt: skip
        else:
            doc, rest = preset_doc(self.words, self.items)
        presets.save(path, doc["method"], doc["params"], doc["groups"], doc.get("about"))
        return rest


def preset_doc(
    words: str | None, items: Sequence[str], named: str | None = None
) -> tuple[dict[str, Any], list[str]]:
    """(the preset document ``words`` + ``items`` name, the items it cannot hold);
    ``named``: how a refusal names the cleaner to the user (default ``--method WORDS``).

    The resolver's reading: a global ``KEY=VALUE`` replaces that key on every channel
    (its per-group values are dropped); ``GROUP.KEY=VALUE`` is the group's value;
    a channel name or a glob stays a ``--set`` item, as do the level items.
    """
    choice = resolve(words, list(items))
    method = choice.method
    cls = filters.cleaner_class(method)
    if method in _LEARNED:
        classical = ", ".join(m for m in filters.METHODS if m not in _LEARNED)
        raise FacecleanError(
            f"{method}: a preset holds a classical cleaner's settings ({classical}); "
            f"give {named or '--method ' + (words or 'default')} and its --set items instead"
        )
    text = words or ""
    if text in presets.shipped() or text.lower().endswith(".json"):
        doc = copy.deepcopy(presets.read(text))
    else:
        doc = {"format": presets.FORMAT, "method": method, "params": {}, "groups": {}}
    params, groups = doc["params"], doc["groups"]
    defaults = _defaults(cls)
    rest = []
    for item in items:
        pattern, key, value = parse_item(item)
        if key in MAP_KEYS or key == "model":
            rest.append(item)
            continue
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise FacecleanError(f"{item}: a preset holds numbers only")
        if pattern is None:
            params[key] = value
            for g in groups.values():
                g.pop(key, None)
        elif pattern.lower() in GROUPS:
            if key not in params and defaults.get(key) is None:
                raise FacecleanError(f"{item}: set {key} for every channel first ({key}=...)")
            params.setdefault(key, defaults.get(key))
            groups.setdefault(pattern.lower(), {})[key] = value
        else:
            rest.append(item)
    doc["groups"] = {g: v for g, v in groups.items() if v}
    about = dict(doc.get("about") or {})
    about["edited"] = "faceclean ui: " + " ".join(items)
    doc["about"] = about
    return doc, rest


# the learned cleaners (models, not presets): every method implemented in faceclean.learned
_LEARNED = tuple(
    m for m, where in filters.METHODS.items() if where.startswith("faceclean.learned.")
)


def _defaults(cls: type) -> dict[str, Any]:
    sig = inspect.signature(cls.__init__)
    return {k: p.default for k, p in sig.parameters.items() if p.default is not inspect._empty}


def json_path(path: str | os.PathLike, what: str) -> None:
    if len(str(path)) > 4096 or not str(path).lower().endswith(".json"):
        raise FacecleanError(f"{str(path)[:80]}: a {what} file is a .json file")
    folder = Path(path).parent
    if not folder.is_dir():
        raise FacecleanError(f"{path}: the folder {folder} does not exist")
