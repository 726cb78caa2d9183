"""Strict JSON, both ways: what faceclean reads from a user and what it prints or writes.

Read (``loads``): RFC 8259 only, an object's keys distinct (a key given twice is
refused: which one was meant?). ``NaN``/``Infinity`` are refused (animation files: read
as they are, see ``loads``), a number must be a finite float64 (``1e400`` and a
400-digit integer are refused, not overflowed), nesting deeper than the parser's
recursion limit is refused; every refusal is one line (FacecleanError). Used for
``--set`` values, presets, model configs, JSON animations and glTF documents.

Write (``dumps``): ``allow_nan=False`` after non-finite floats became ``null``
(``info --json``); a writer that must not lose them refuses them itself (io.json_format).
"""

from __future__ import annotations

import json
import math
from typing import Any

from faceclean.errors import FacecleanError

MAX_INT_DIGITS = 18  # longer integers are read as floats (must still be finite)
MAX_DEPTH = 64  # nesting of the values cleaners take (lists of lists ...)


def _constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def _float(text: str) -> float:
    v = float(text)
    if not math.isfinite(v):
        raise ValueError(f"number {text[:20]}... is beyond float64")
    return v


def _int(text: str) -> int | float:
    digits = text.lstrip("-")
    return int(text) if len(digits) <= MAX_INT_DIGITS else _float(text)


def _object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """An object whose keys are distinct (a key given twice is ambiguous: which one?)."""
    out = dict(pairs)
    if len(out) < len(pairs):
        seen: set[str] = set()
        twice = next(k for k, _ in pairs if k in seen or seen.add(k))
        raise ValueError(f"key {twice[:40]!r} given twice")
    return out


def loads(
    text: str | bytes, label: str, *, numbers: bool = True, max_depth: int | None = None
) -> Any:
    """Parse strict JSON; FacecleanError ``<label>: not valid JSON (reason)`` otherwise.

    ``numbers=False`` (animation files: their readers check the arrays with numpy, and a
    NaN or infinite cell is read as it is) skips the per-number checks and accepts the
    ``NaN``/``Infinity`` spellings Python writes; depth is bounded either way (by the
    parser's recursion limit; ``max_depth``: by that many levels of lists and objects, so
    that code walking the value recursively never meets a RecursionError).
    """
    hooks: dict[str, Any] = {"parse_float": _float, "parse_int": _int} if numbers else {}
    hooks["object_pairs_hook"] = _object
    if numbers:
        hooks["parse_constant"] = _constant
    try:
        doc = json.loads(text, **hooks)
    except RecursionError:
        raise FacecleanError(f"{label}: not valid JSON (nested too deep)") from None
    except (ValueError, UnicodeDecodeError) as e:  # JSONDecodeError is a ValueError
        reason = " ".join(str(e).split())[:120]
        raise FacecleanError(f"{label}: not valid JSON ({reason})") from None
    if max_depth is not None and depth(doc, max_depth + 1) > max_depth:
        raise FacecleanError(f"{label}: nested deeper than {max_depth} levels")
    return doc


def value(text: str) -> Any:
    """A ``--set`` value: its strict JSON reading, else the text itself (a name such as
    ``auto``); a cleaner's own checks then refuse what is not a usable number."""
    try:
        return loads(text, "value")
    except FacecleanError:
        return text


def depth(value: Any, limit: int = MAX_DEPTH) -> int:
    """Nesting depth of lists and dicts (a scalar is 0); stops counting past ``limit``."""
    if isinstance(value, list | tuple | dict) and limit > 0:
        items = value.values() if isinstance(value, dict) else value
        return 1 + max((depth(v, limit - 1) for v in items), default=0)
    return 0


def finite(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None (lists, tuples, dicts)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    return value


def dumps(value: Any, **kwargs: Any) -> str:
    """Strict JSON text: non-finite floats become null (never ``Infinity``)."""
    return json.dumps(finite(value), allow_nan=False, **kwargs)
