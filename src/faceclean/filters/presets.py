"""Presets: a classical cleaner's parameters, global and per channel group, as JSON.

Layout (``faceclean-preset/1``)::

    {"format": "faceclean-preset/1",
     "method": "one-euro",
     "params": {"min_cutoff": 1.2, "beta": 0.4, "d_cutoff": 1.0},
     "groups": {"eyes": {"min_cutoff": 3.0, "beta": 2.0}, "mouth": {...}, ...},
     "about": {...}}

``params`` apply to every channel; ``groups`` (names from faceclean.channels.GROUPS:
eyes, brows, jaw, mouth, cheeks_nose; for the head/eye angles of the ``rotation``
method, POSE_GROUPS: head, eyes) override them for that group's channels. Values
are plain numbers in the cleaner's physical units. ``about`` is free-form provenance
(how and on what the preset was tuned). Parsing is strict and never unpickles anything.
Shipped presets live in ``faceclean/presets/<name>.json`` and are found by name.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from faceclean import strict_json
from faceclean.channels import ARKIT52, GROUPS, POSE_GROUPS, group_of
from faceclean.errors import FacecleanError
from faceclean.filters import METHODS, Stepper, make
from faceclean.io.atomic import atomic_write
from faceclean.io.source import named, read_json
from faceclean.settings import PRESETS

FORMAT = "faceclean-preset/1"
_KEYS = {"format", "method", "params", "groups", "about"}


def shipped() -> list[str]:
    """Names of the presets that ship with faceclean."""
    return sorted(p.stem for p in PRESETS.glob("*.json")) if PRESETS.is_dir() else []


def locate(preset: str | os.PathLike) -> Path:
    """A preset file: an existing path, else the shipped preset of that name."""
    p = Path(preset)
    if isinstance(preset, str) and os.sep not in preset and not preset.endswith(".json"):
        if p.is_file():  # a bare name ("ema"): a file of that name, else the shipped one
            return p  # (a folder or FIFO named like a method is not meant: out/ema/)
        q = PRESETS / f"{preset}.json"
        if q.is_file():
            return q
        raise FacecleanError(
            f"no preset file or shipped preset named {preset!r} "
            f"(shipped: {', '.join(shipped()) or 'none'})"
        )
    if named(p):  # the user's file, whatever it is: the reader says what is wrong with it
        return p
    raise FacecleanError(f"no such preset file: {p}")


def _numbers(d: Any, where: str) -> dict[str, float]:
    if not isinstance(d, dict):
        raise FacecleanError(f"{where} must be an object of name: number")
    for k, v in d.items():
        ok = isinstance(v, int | float) and not isinstance(v, bool) and _finite(v)
        if not ok:
            got = strict_json.dumps(v)[:40] if strict_json.depth(v, 3) < 3 else "a nested value"
            raise FacecleanError(f"{where}.{k} must be a finite number (got {got})")
    return dict(d)


def _finite(v: float) -> bool:
    try:
        return math.isfinite(v) and abs(float(v)) < 1e300
    except OverflowError:  # an int beyond float64
        return False


def validate(doc: Any, source: str = "preset") -> dict[str, Any]:
    """Check a parsed preset; returns it with ``groups`` filled in ({} when absent)."""
    if not isinstance(doc, dict):
        raise FacecleanError(f"{source}: a preset is a JSON object")
    extra = set(doc) - _KEYS
    if extra:
        raise FacecleanError(f"{source}: unknown key(s) {', '.join(sorted(extra))}")
    if doc.get("format") != FORMAT:
        raise FacecleanError(f"{source}: format must be {FORMAT!r} (got {doc.get('format')!r})")
    method = doc.get("method")
    if not isinstance(method, str) or method not in METHODS:
        raise FacecleanError(
            f"{source}: unknown method {method!r:.60} (known: {', '.join(METHODS)})"
        )
    params = _numbers(doc.get("params", {}), f"{source}: params")
    groups = doc.get("groups", {})
    if not isinstance(groups, dict):
        raise FacecleanError(f"{source}: groups must be an object")
    known = {**GROUPS, **POSE_GROUPS}
    for g in groups:
        if g not in known:
            raise FacecleanError(f"{source}: unknown group {g!r} (known: {', '.join(known)})")
    groups = {g: _numbers(v, f"{source}: groups.{g}") for g, v in groups.items()}
    if "about" in doc and not isinstance(doc["about"], dict):
        raise FacecleanError(f"{source}: about must be an object")
    return {**doc, "params": params, "groups": groups}


def read(preset: str | os.PathLike) -> dict[str, Any]:
    """Load and validate a preset (a path or a shipped name)."""
    p = locate(preset)
    return validate(read_json(p, "preset file", 1 << 20), p.name)


def expand(doc: Mapping[str, Any], names: Sequence[str]) -> dict[str, float | np.ndarray]:
    """Keyword parameters for ``names``: a scalar where all channels agree, else (M,)."""
    params, groups = doc.get("params", {}), doc.get("groups", {})
    keys = list(params) + [k for g in groups.values() for k in g if k not in params]
    channel_group = [group_of(n) for n in names]
    out: dict[str, float | np.ndarray] = {}
    for k in dict.fromkeys(keys):
        vals = []
        for n, g in zip(names, channel_group, strict=True):
            v = groups.get(g, {}).get(k, params.get(k)) if g else params.get(k)
            if v is None:
                raise FacecleanError(
                    f"preset: {k} is set for some groups only; give a default in params "
                    f"(channel {n} has none)"
                )
            vals.append(float(v))
        a = np.array(vals)  # (M,)
        out[k] = float(a[0]) if len(a) and np.all(a == a[0]) else a
    return out


def build(
    preset: str | os.PathLike | Mapping[str, Any],
    names: Sequence[str] = ARKIT52,
    overrides: Mapping[str, Any] | None = None,
) -> Stepper:
    """The cleaner a preset describes, for channels ``names``.

    ``preset``: a file path, a shipped preset's name (e.g. "one-euro") or a parsed dict.
    ``overrides`` replace parameters for every channel (e.g. from ``--set``).
    """
    doc = validate(dict(preset), "preset") if isinstance(preset, Mapping) else read(preset)
    params: dict[str, Any] = expand(doc, names)
    params.update(overrides or {})
    return make(doc["method"], params, names=names)


def save(
    path: str | os.PathLike,
    method: str,
    params: Mapping[str, float],
    groups: Mapping[str, Mapping[str, float]] | None = None,
    about: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Write a preset atomically (validated first); returns the document written."""
    doc: dict[str, Any] = {"format": FORMAT, "method": method, "params": dict(params)}
    if groups:
        doc["groups"] = {g: dict(v) for g, v in groups.items()}
    if about:
        doc["about"] = dict(about)
    validate(doc, Path(path).name)
    atomic_write(path, json.dumps(doc, indent=2) + "\n")
    return doc
