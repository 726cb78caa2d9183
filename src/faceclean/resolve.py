"""From a user's words to a cleaner: the one answer to "which cleaner?".

Words (``clean --method``, ``relay``, ``plot``/``report``, ``eval``, ``Cleaner.load``):

- None or ``"default"``: the shipped default model (``models/default.npz``); ``lstm``,
  ``adaptive``, ``fc``, ``gbt``: that shipped model (``SHIPPED_MODELS``);
- a model file: ``.npz`` (an LSTM, FC or GBT checkpoint, told apart by its format) or an
  exported ``.onnx`` step graph;
- a preset: a ``.json`` file written by ``faceclean tune``, or a shipped preset's name;
- a method name (``faceclean.filters.METHODS``): its shipped tuned preset when one
  exists, else its constructor defaults; ``fc``/``gbt`` are their shipped models.

Settings (``--set``, repeatable; inline as ``WORDS:ITEM,ITEM`` for ``--compare``):

- ``KEY=VALUE`` sets a parameter of the cleaner for every channel; on a tuned preset it
  replaces that key only and keeps the rest of the preset;
- ``PATTERN.KEY=VALUE`` sets it for the channels PATTERN names: a channel name,
  a glob on the canonical name (``eyeBlink*``) or a group (``eyes``, ``mouth``, ...);
  only the per-channel smoothing parameters of the classical cleaners take a pattern;
- the level-mapping keys of ``faceclean.adjust`` (``gain``, ``offset``, ``curve``,
  ``clamp``, ``off``; ``eyeBlink*.gain=1.2``, ``tongueOut.off``) are returned apart as
  ``Choice.levels``, applied to the raw values before the cleaner.

VALUE is read one way everywhere: true/false (also yes/no, on/off), else JSON (numbers,
lists, quoted strings, null), else the text itself. ``-`` in a key reads as ``_``. An
unknown key is a one-line FacecleanError listing the valid ones.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from faceclean import filters
from faceclean.adjust import MAP_KEYS, matches
from faceclean.channels import ARKIT52, GROUPS, POSE
from faceclean.errors import FacecleanError

DEFAULT = "default"  # the shipped learned model (models/default.npz)
MODEL_SUFFIXES = (".npz", ".onnx")
# method word -> its shipped file; else models/default.npz when that is of this method
SHIPPED_MODELS = {"lstm": "lstm.npz", "adaptive": "adaptive.npz", "fc": "fc.npz", "gbt": "gbt.npz"}
# tracker (channels.TRACKERS, the one list of trackers) -> the shipped cleaner made for its
# output; a tracker not named here gets the default (made for ARKit)
TRACKER_MODELS = {"mediapipe": "mediapipe.npz"}
BACKENDS = ("numpy", "onnx")
Item = tuple[str | None, str, Any]  # (channel pattern or None for every channel, key, value)
Factory = Callable[[Sequence[str]], filters.Stepper]
_HIDDEN = {"path", "model"}  # the model file is in the words, not a setting


def parse_value(text: str) -> Any:
    """A setting's value: true/false/yes/no/on/off, else JSON, else the text."""
    t = text.strip()
    low = t.lower()
    if low in ("true", "yes", "on"):
        return True
    if low in ("false", "no", "off"):
        return False
    from faceclean import strict_json

    return strict_json.value(t)  # strict JSON (no NaN, no 1e400, no deep lists), else the text


def parse_item(item: str) -> Item:
    """``"min_cutoff=2"`` -> (None, "min_cutoff", 2); ``"jawOpen.beta=0.1"`` -> ("jawOpen",
    "beta", 0.1); ``"tongueOut.off"`` -> ("tongueOut", "off", None)."""
    lhs, eq, text = item.partition("=")
    pattern, dot, key = lhs.strip().rpartition(".")
    key = key.strip().replace("-", "_")
    if not key or (dot and not pattern.strip()):
        raise FacecleanError(f"--set {item!r}: expected KEY=VALUE or CHANNEL.KEY=VALUE")
    if not eq and key != "off":
        near = difflib.get_close_matches(key.lower(), ("off",), n=1, cutoff=0.5)
        if near:  # "tongueOut.of": a key without a value is only ever "off"
            fixed = f"{pattern.strip()}.off" if dot else "off"
            raise FacecleanError(
                f"--set {item!r}: did you mean {fixed!r}? (expected KEY=VALUE, or CHANNEL.off)"
            )
        raise FacecleanError(f"--set {item!r}: expected KEY=VALUE (or CHANNEL.off)")
    return (pattern.strip() or None), key, (parse_value(text) if eq else None)


def parse_items(items: Iterable[str] | Mapping[str, Any]) -> list[Item]:
    """Settings from ``--set`` words, or from a mapping {"jawOpen.beta": 0.1, ...}."""
    if isinstance(items, Mapping):
        out = []
        for k, v in items.items():
            pattern, _, key = str(k).rpartition(".")
            out.append((pattern or None, key.replace("-", "_"), v))
        return out
    return [parse_item(s) for s in items]


def split_spec(spec: str) -> tuple[str, list[str]]:
    """``"one-euro:min_cutoff=1.5,jawOpen.beta=0.3"`` -> ("one-euro", ["min_cutoff=1.5",
    "jawOpen.beta=0.3"]); commas inside brackets stay with their item. A path that exists
    is never split."""
    spec = spec.strip()
    if ":" not in spec or _exists(spec):
        return spec, []
    words, _, rest = spec.partition(":")
    items, depth, start = [], 0, 0
    for i, ch in enumerate(rest + ","):
        depth += ch in "[{"
        depth -= ch in "]}"
        if ch == "," and depth <= 0:
            if rest[start:i].strip():
                items.append(rest[start:i].strip())
            start = i + 1
    if not words.strip():
        raise FacecleanError(f"{spec!r}: no method name before ':'")
    return words.strip(), items


def _exists(path: str) -> bool:
    try:
        return Path(path).exists()
    except (OSError, ValueError):  # a name too long for the file system, a NUL byte
        return False


@dataclass(frozen=True)
class Choice:
    """What the words named: ``build(names)`` makes a fresh cleaner for those channels."""

    method: str  # the cleaner's method name ("one-euro", "lstm", ...)
    source: str  # how to name it to a user ("one-euro (tuned preset) min_cutoff=2")
    offline: bool  # non-causal: clean() only
    factory: Factory = field(repr=False)
    levels: tuple[tuple[str, str, Any], ...] = ()  # (pattern, key, value) for faceclean.adjust
    pose: Factory | None = field(default=None, repr=False)  # head/eye angles' cleaner
    pose_source: str = ""  # how to name it ("rotation (tuned preset) head.beta=2")

    def build(self, names: Sequence[str] = ARKIT52) -> filters.Stepper:
        return self.factory(tuple(names))

    def build_pose(self, names: Sequence[str] = POSE) -> filters.Stepper:
        """A fresh rotation cleaner for head/eye angle channels ``names``."""
        factory = self.pose or pose_factory([])[0]
        return factory(tuple(names))

    def adjust(self, names: Sequence[str] = ARKIT52):
        """The level mapping the settings ask for (faceclean.adjust.Adjust)."""
        from faceclean.adjust import Adjust

        return Adjust.from_overrides(self.levels, names)


def resolve(
    words: str | os.PathLike | None = None,
    settings: Iterable[str] | Mapping[str, Any] = (),
    *,
    backend: str | None = None,
    pose_preset: str | os.PathLike | None = None,
) -> Choice:
    """The cleaner ``words`` name (module docstring), with ``settings`` applied.

    backend: "numpy" (the torch-free runtime) or "onnx" (ONNX Runtime) for learned
    models; None: numpy for .npz, onnx for .onnx. ``pose_preset``: a ``rotation`` preset
    (``faceclean tune --method rotation``) for the head/eye angles instead of the shipped
    one; the ``head.*``/``eyes.*`` settings go on top of it.
    """
    if backend is not None and backend not in BACKENDS:
        raise FacecleanError(f"unknown backend {backend!r} (known: {', '.join(BACKENDS)})")
    if isinstance(words, str) and not isinstance(settings, Mapping):
        words, inline = split_spec(words)
        settings = [*inline, *settings]
    items = parse_items(settings)
    levels = tuple((p or "*", k, v) for p, k, v in items if k in MAP_KEYS)
    items = [it for it in items if it[1] not in MAP_KEYS]
    items, shared, pose_items = _split_pose(items)
    text = "" if words is None else str(words)
    model = [v for p, k, v in items if k == "model"]
    if model:  # "--method lstm --set model=FILE" is "--model FILE"
        if text not in ("", *SHIPPED_MODELS) or len(model) > 1 or not isinstance(model[0], str):
            raise FacecleanError("model=FILE goes with a learned method (lstm, fc, gbt), once")
        text, items = model[0], [it for it in items if it[1] != "model"]
    if text in ("", "default", *SHIPPED_MODELS):
        from faceclean.settings import MODELS

        own = MODELS / SHIPPED_MODELS.get(text, "default.npz")
        choice = _model(own if own.is_file() else MODELS / "default.npz", items, backend, shared)
        if text not in ("", "default") and choice.method != text:
            raise FacecleanError(f"no shipped {text} model (the default is {choice.method})")
    elif text.lower().endswith(MODEL_SUFFIXES):
        choice = _model(Path(text), items, backend, shared)
    else:
        if backend == "onnx":
            raise FacecleanError("the onnx backend runs learned models only")
        choice = _classical(text, items, shared)
    per = getattr(filters.cleaner_class(choice.method), "PER_CHANNEL", ())
    for pattern, key, _ in shared:  # an eyes.KEY that neither side has
        if key not in per and key not in _POSE_KEYS:
            raise FacecleanError(
                f"{pattern}.{key}: {key} is neither a per-channel setting of "
                f"{choice.method} nor one of the rotation filter's ({', '.join(_POSE_KEYS)})"
            )
    pose_items += [it for it in shared if it[1] in _POSE_KEYS]
    pose, pose_source = pose_factory(pose_items, pose_preset)
    return dataclasses.replace(choice, levels=levels, pose=pose, pose_source=pose_source)


_POSE_KEYS = ("min_cutoff", "beta", "d_cutoff")  # filters.rotation.Rotation.PER_CHANNEL


def _split_pose(items: list[Item]) -> tuple[list[Item], list[Item], list[Item]]:
    """(blendshape items, items naming both the eye blendshapes and angles, angle items)."""
    from faceclean.filters.rotation import pose_matches

    blend, shared, pose = [], [], []
    for it in items:
        pattern = it[0]
        angles = pattern is not None and any(pose_matches(pattern, n) for n in POSE)
        if not angles:
            blend.append(it)
        elif any(matches(pattern, n) for n in ARKIT52):
            shared.append(it)
        else:
            pose.append(it)
    return blend, shared, pose


def pose_factory(items: list[Item], preset: str | os.PathLike | None = None) -> tuple[Factory, str]:
    """The head/eye angles' cleaner: ``preset`` (a rotation preset; default the shipped
    tuned one) with ``items`` (pattern, key, value) on top; (factory(names), its name)."""
    from faceclean.filters import presets
    from faceclean.filters.rotation import Rotation, pose_matches

    if preset is not None:
        doc = presets.read(preset)
        if doc["method"] != "rotation":
            raise FacecleanError(
                f"{preset}: a {doc['method']} preset, not one for head and eye angles "
                "(faceclean tune --method rotation makes those)"
            )
    else:
        doc = presets.read("rotation") if "rotation" in presets.shipped() else None
    for pattern, key, value in items:
        if key not in Rotation.PER_CHANNEL:
            raise FacecleanError(
                f"{pattern}.{key}: the rotation filter (head and eye angles) has no setting "
                f"{key!r}; valid: {', '.join(Rotation.PER_CHANNEL)}"
            )
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise FacecleanError(f"{pattern}.{key}: expected a number (got {value!r})")

    def factory(names: Sequence[str]) -> filters.Stepper:
        params: dict[str, Any] = presets.expand(doc, names) if doc else {}
        for pattern, key, value in items:
            base = params.get(key, getattr(Rotation(names=names), key))
            out = np.array(np.broadcast_to(base, (len(names),)), dtype=np.float64)
            out[[j for j, n in enumerate(names) if pose_matches(pattern, n)]] = value
            params[key] = out
        return filters.make("rotation", params, names=names)

    factory(POSE)  # bad values fail now, with the parameter's reason
    what = "rotation (tuned preset)" if doc else "rotation (defaults)"
    what = f"rotation (preset {preset})" if preset is not None else what
    return factory, _shown(what, items)


def tracker_words(tracker: str | None) -> str | None:
    """The words for the cleaner shipped for ``tracker`` (None: the default)."""
    from faceclean.channels import TRACKERS

    if tracker is None:
        return None
    key = str(tracker).strip().lower()
    if key not in TRACKERS:
        raise FacecleanError(f"unknown tracker {tracker!r} (known: {', '.join(TRACKERS)})")
    if key not in TRACKER_MODELS:
        return None
    from faceclean.settings import MODELS

    path = MODELS / TRACKER_MODELS[key]
    if not path.is_file():
        raise FacecleanError(f"no shipped cleaner for {key} in this install ({path.name})")
    return str(path)


def model_file(words: str | os.PathLike) -> Path:
    """The model file ``words`` name: a shipped model's name (``default``, ``lstm``, ...:
    its file in the package) or a path; one line when it is neither."""
    from faceclean.settings import MODELS

    text = str(words)
    if text in (DEFAULT, *SHIPPED_MODELS):
        own = MODELS / SHIPPED_MODELS.get(text, "default.npz")
        return own if own.is_file() else MODELS / "default.npz"
    path = Path(text)
    if not _exists(text) or not path.is_file():
        shipped = ", ".join([DEFAULT, *SHIPPED_MODELS])
        raise FacecleanError(f"no such model file: {path} (or a shipped model: {shipped})")
    return path


def _model(path: Path, items: list[Item], backend: str | None, shared: list[Item] = ()) -> Choice:
    """A learned model file: the class from its format, settings as keywords; ``shared``
    items (``eyes.KEY``) are taken where KEY is one of its per-channel settings."""
    from faceclean.learned import formats

    formats.model_file(path)  # missing, a FIFO, a device or a folder: one line saying so
    onnx = path.suffix.lower() == ".onnx"
    backend = backend or ("onnx" if onnx else "numpy")
    if backend == "onnx":
        from faceclean.learned.onnx import OnnxLearned, model_bytes

        graph = model_bytes(path)
        params = _checked(OnnxLearned, "lstm", items, per_channel=())
        OnnxLearned(graph, **params)  # fail now, with the file's reason
        return Choice(
            "lstm",
            _shown(f"lstm (onnx) {path}", items),
            False,
            lambda names: OnnxLearned(graph, names=names, **params),
        )
    if onnx:
        raise FacecleanError(f"{path.name}: an ONNX graph runs on backend='onnx'")
    method = formats.method_of(path)
    cls = filters.cleaner_class(method)
    per = tuple(getattr(cls, "PER_CHANNEL", ()))  # the adaptive model: One Euro's keys
    items = [*items, *(it for it in shared if it[1] in per)]
    params = _checked(cls, method, items, per_channel=per)
    _known_patterns(items)
    probe = filters.make(method, {"model": path, **params})  # bad settings fail now
    weights = getattr(probe, "weights", None)  # read once, shared by every build
    source = {"model": path} if weights is None else {"weights": weights}

    def factory(names: Sequence[str]) -> filters.Stepper:
        def build(p: dict[str, Any]) -> filters.Stepper:
            return cls(names=names, **source, **p)

        kw = dict(params)
        for pattern, key, value in items:
            if pattern is not None:
                kw[key] = _scoped(build, kw, names, pattern, key, value)
        return build(kw)

    if any(p is not None for p, _, _ in items):
        factory(ARKIT52)  # bad per-channel values fail now
    what = f"{method} {path}" if weights is None else f"{method} (numpy) {path}"
    return Choice(method, _shown(what, items), False, factory)


def _classical(text: str, items: list[Item], shared: list[Item] = ()) -> Choice:
    """A preset (file or shipped name) or a method name; ``shared`` items (``eyes.KEY``)
    are taken where KEY is one of the method's per-channel settings."""
    from faceclean.filters import presets

    doc: dict[str, Any] | None = None
    if text in filters.METHODS:
        method, tuned = text, text in presets.shipped()
        doc = presets.read(text) if tuned else None
        what = f"{text} (tuned preset)" if tuned else f"{text} (defaults)"
    elif text.lower().endswith(".json") or text in presets.shipped():
        doc = presets.read(text)  # validated once
        method = doc["method"]
        what = f"{method} (preset {text})"
    else:
        raise FacecleanError(
            f"unknown method {text!r}: no model, preset or method of that name (methods: "
            f"{', '.join(filters.METHODS)}; presets: {', '.join(presets.shipped())}; "
            "or a model file .npz/.onnx)"
        )
    cls = filters.cleaner_class(method)
    per = tuple(getattr(cls, "PER_CHANNEL", ()))
    items = [*items, *(it for it in shared if it[1] in per)]
    _checked(cls, method, items, per)
    _known_patterns(items)

    def factory(names: Sequence[str]) -> filters.Stepper:
        def build(p: dict[str, Any]) -> filters.Stepper:
            return filters.make(method, p, names=names)

        params: dict[str, Any] = presets.expand(doc, names) if doc else {}
        for pattern, key, value in items:
            if pattern is None:
                params[key] = value
            else:
                params[key] = _scoped(build, params, names, pattern, key, value)
        return build(params)

    factory(ARKIT52)  # bad values fail now, with the parameter's reason
    return Choice(method, _shown(what, items), bool(cls.offline), factory)


def _checked(cls: type, method: str, items: list[Item], per_channel: tuple[str, ...]) -> dict:
    """Global settings as keywords, after checking every key (one line, valid keys)."""
    valid = [k for k in filters.settings_of(cls) if k not in _HIDDEN]
    for pattern, key, _ in items:
        if key not in valid:
            near = difflib.get_close_matches(key, [*valid, *MAP_KEYS], n=1, cutoff=0.7)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise FacecleanError(f"{method}: unknown setting {key!r}{hint}; valid: {_valid(valid)}")
        if pattern is not None and key not in per_channel:
            scoped = ", ".join(per_channel) or "none"
            raise FacecleanError(
                f"{method}: {pattern}.{key}: {key} is not per channel "
                f"(per-channel settings: {scoped}; levels: {', '.join(MAP_KEYS)})"
            )
    return {k: v for p, k, v in items if p is None}


def _valid(valid: list[str]) -> str:
    return f"{', '.join(valid)}; per channel PATTERN.KEY; levels {', '.join(MAP_KEYS)}"


def _known_patterns(items: list[Item]) -> None:
    for pattern, key, _ in items:
        if pattern is not None and not any(matches(pattern, n) for n in ARKIT52):
            raise FacecleanError(
                f"{pattern}.{key}: {pattern!r} names no channel (a channel name, a glob "
                f"such as 'eyeBlink*', or a group: {', '.join(GROUPS)})"
            )


def _scoped(
    build: Callable[[dict[str, Any]], filters.Stepper],
    params: dict[str, Any],
    names: Sequence[str],
    pattern: str,
    key: str,
    value: Any,
) -> np.ndarray:
    """``key`` as (M,) values with ``value`` on the channels ``pattern`` names (none of
    these channels: unchanged), the others as ``params`` (or the defaults) give them;
    ``build(params)`` makes the cleaner whose ``key`` is read."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise FacecleanError(f"{pattern}.{key}: expected a number (got {value!r})")
    base = getattr(build(params), key)  # 0-d or (M,)
    if base is None:
        raise FacecleanError(f"{pattern}.{key}: set {key} for every channel first ({key}=...)")
    out = np.array(np.broadcast_to(base, (len(names),)), dtype=np.float64)
    out[[j for j, n in enumerate(names) if matches(pattern, n)]] = value
    return out


def _shown(what: str, items: list[Item]) -> str:
    if not items:
        return what
    return what + " " + ", ".join(f"{p + '.' if p else ''}{k}={json.dumps(v)}" for p, k, v in items)
