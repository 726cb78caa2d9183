"""A tracker map's weights (learned/tracker_map.py): its config and arrays, validated.

Checkpoint (.npz, no pickle): ``config`` JSON {"format": FORMAT, "inputs": [K],
"outputs": [M], "hidden": H, "rest": bool, "prefilter": bool, "deadband": eps (a number
or M of them, weight units, 0 if absent), ...facts}; arrays
``min_cutoff``, ``beta``, ``d_cutoff`` (K,) Hz; ``mu``, ``sd`` (2K,); ``w1`` (H, 2K),
``b1`` (H,), ``w2`` (M, H), ``b2`` (M,), ``a`` (M, K), ``b`` (M, K), ``c`` (M,); optional
``lift_gain`` >= 0 and ``lift_knee`` in [0, 1] (M,) (absent: no lift; a gain > 0 needs an
input of the output's name); optional ``detail`` (M,) within [-MAX_DETAIL, MAX_DETAIL]
(absent: 0; nonzero needs an input of the output's name, as the lift does), the fitted
gains, which run scaled by the config's ``detail_scale`` in [0, 1] (absent: 1) or by the
user's ``detail`` setting; config ``lift_top`` true or false (absent: false); config
``lift_cutoff`` in (0, MAX_CUTOFF] Hz (absent: LIFT_CUTOFF), the low-pass the lift reads
its raw input through (learned/tracker_map.py); config
``noise_band`` c in [0, MAX_NOISE] (absent: 0), the band's widening (learned/band.py);
config ``rest_tau`` and ``rest_warm`` in [0, MAX_REST] s, a number or one per input (absent:
0), the rest's smoothing and warm-up (learned/tracker_map.py); config ``rest_drift`` in
[0, MAX_DRIFT] weight/s, a number or one per input (absent: 0), how fast the rest may climb
back up toward the face's reading, so that a dip is forgotten.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from faceclean.errors import FacecleanError
from faceclean.learned import formats
from faceclean.learned.formats import TRACKER_MAP as FORMAT

MAX_WIDTH = 4096
MAX_DEADBAND = 0.1  # weight units: a larger band would hold real movement
MAX_LIFT = 20.0  # a lift's gain: more would turn the tracker's noise into blinks
MAX_DETAIL = 4.0  # the detail's gain: more would pass the raw input's noise amplified
MAX_CUTOFF = 100.0  # Hz: a lift's low-pass; more passes a 60 fps stream's noise as it is
LIFT_CUTOFF = 4.0  # Hz, the lift's low-pass where a file names none (docs/MODEL.md 22nd)
MAX_NOISE = 100.0  # the band over the noise: more would hold a face still through its moves
MAX_REST = 10.0  # s: a rest smoothed or held off longer would miss a face's own rest
MAX_DRIFT = 1.0  # weight/s: a rest climbing faster would take a held expression off in 1 s
REST_KEYS = ("rest_tau", "rest_warm", "rest_drift")


@dataclass(frozen=True)
class MapWeights:
    """A tracker map's config and arrays (float64), validated."""

    config: dict[str, Any]
    arrays: dict[str, np.ndarray]

    @property
    def inputs(self) -> tuple[str, ...]:
        return tuple(self.config["inputs"])

    @property
    def outputs(self) -> tuple[str, ...]:
        return tuple(self.config["outputs"])

    @property
    def lift_tau(self) -> float:
        """s: the time constant 1 / (2 pi f) of the lift's low-pass (``lift_cutoff`` f Hz)."""
        return 1.0 / (2.0 * np.pi * float(self.config.get("lift_cutoff", LIFT_CUTOFF)))

    @property
    def rest(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rest_tau s, rest_warm s, rest_drift weight/s) (K,) each, one per input (config:
        a number or one per input, absent 0: the plain running minimum)."""
        k = len(self.inputs)
        return tuple(  # type: ignore[return-value]
            np.broadcast_to(np.asarray(self.config.get(key, 0.0), np.float64), (k,))
            for key in REST_KEYS
        )

    @classmethod
    def load(cls, path: str | os.PathLike) -> MapWeights:
        config, arrays = formats.read(path)
        return cls.build(config, arrays, Path(path).name)

    @classmethod
    def build(cls, config: dict, arrays: dict, label: str = "tracker map") -> MapWeights:
        if config.get("format") != FORMAT:
            raise FacecleanError(f"{label}: not a {FORMAT} model")
        try:
            k, m = len(config["inputs"]), len(config["outputs"])
            h = int(config["hidden"])
            names_ok = all(isinstance(n, str) for n in [*config["inputs"], *config["outputs"]])
        except (KeyError, TypeError, ValueError):
            raise FacecleanError(f"{label}: config lacks inputs, outputs or hidden") from None
        if not (names_ok and 1 <= k <= MAX_WIDTH and 1 <= m <= MAX_WIDTH and 0 <= h <= MAX_WIDTH):
            raise FacecleanError(f"{label}: bad inputs/outputs/hidden in config")
        if len(set(config["inputs"])) != k or len(set(config["outputs"])) != m:
            raise FacecleanError(f"{label}: channel names repeat")
        shapes = {
            "min_cutoff": (k,),
            "beta": (k,),
            "d_cutoff": (k,),
            "mu": (2 * k,),
            "sd": (2 * k,),
            "w1": (h, 2 * k),
            "b1": (h,),
            "w2": (m, h),
            "b2": (m,),
            "a": (m, k),
            "b": (m, k),
            "c": (m,),
        }
        out = {}
        for key, shape in shapes.items():
            a = arrays.get(key)
            if a is None or tuple(np.shape(a)) != shape or not np.issubdtype(a.dtype, np.number):
                raise FacecleanError(f"{label}: array {key!r} missing or not of shape {shape}")
            a = np.asarray(a, np.float64)
            if not np.isfinite(a).all():
                raise FacecleanError(f"{label}: array {key!r} is not finite")
            out[key] = a
        if (out["sd"] <= 0).any() or (out["min_cutoff"] <= 0).any() or (out["d_cutoff"] <= 0).any():
            raise FacecleanError(f"{label}: scales and cut-offs must be > 0")
        if (out["beta"] < 0).any():
            raise FacecleanError(f"{label}: beta must be >= 0")
        limits = (("lift_gain", (0.0, MAX_LIFT)), ("lift_knee", (0.0, 1.0)),
                  ("detail", (-MAX_DETAIL, MAX_DETAIL)))  # fmt: skip
        for key, (lo, hi) in limits:
            a = arrays.get(key, np.zeros(m))
            if tuple(np.shape(a)) != (m,) or not np.issubdtype(np.asarray(a).dtype, np.number):
                raise FacecleanError(f"{label}: array {key!r} not of shape {(m,)}")
            a = np.asarray(a, np.float64)
            if not (np.isfinite(a).all() and (a >= lo).all() and (a <= hi).all()):
                raise FacecleanError(f"{label}: {key} must be within [{lo:g}, {hi:g}]")
            out[key] = a
        for key, what in (("lift_gain", "is lifted"), ("detail", "has a detail")):
            own = [o for o, g in zip(config["outputs"], out[key], strict=True) if g != 0]
            if set(own) - set(config["inputs"]):
                name = sorted(set(own) - set(config["inputs"]))[0]
                raise FacecleanError(f"{label}: output {name!r} {what} but is not an input")
        try:
            band = np.broadcast_to(np.asarray(config.get("deadband", 0.0), np.float64), (m,))
        except (TypeError, ValueError):
            raise FacecleanError(f"{label}: deadband must be a number or one per output") from None
        if not (np.isfinite(band).all() and (band >= 0).all() and (band <= MAX_DEADBAND).all()):
            raise FacecleanError(f"{label}: deadband must be within [0, {MAX_DEADBAND}]")
        if not isinstance(config.get("lift_top", False), bool):
            raise FacecleanError(f"{label}: lift_top must be true or false")
        fc = config.get("lift_cutoff", LIFT_CUTOFF)
        if isinstance(fc, bool) or not isinstance(fc, (int, float)) or not 0 < fc <= MAX_CUTOFF:
            raise FacecleanError(f"{label}: lift_cutoff must be a number of Hz within "
                                 f"(0, {MAX_CUTOFF:g}]")  # fmt: skip
        c = config.get("noise_band", 0.0)
        if isinstance(c, bool) or not isinstance(c, (int, float)) or not 0 <= c <= MAX_NOISE:
            raise FacecleanError(f"{label}: noise_band must be a number within [0, {MAX_NOISE}]")
        for key, top, unit in zip(REST_KEYS, (MAX_REST, MAX_REST, MAX_DRIFT),
                                  ("seconds", "seconds", "weight/s"), strict=True):  # fmt: skip
            v = config.get(key, 0.0)
            values = v if isinstance(v, list) and len(v) == k else [v]
            if not all(not isinstance(x, bool) and isinstance(x, (int, float))
                       and 0 <= x <= top for x in values):  # fmt: skip
                raise FacecleanError(f"{label}: {key} must be a number of {unit} within "
                                     f"[0, {top:g}], or one per input")  # fmt: skip
        scale = config.get("detail_scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 <= scale <= 1:
            raise FacecleanError(f"{label}: detail_scale must be a number within [0, 1]")
        return cls(dict(config), out)

    def save(self, path: str | os.PathLike) -> None:
        """Write the map, once ``formats.write`` has checked it: every array finite, and
        the file as written loads (``build``); else one line, and nothing written."""
        label = Path(path).name
        formats.write(path, self.config, self.arrays,
                      lambda a: MapWeights.build(*formats.split(a, label), label))  # fmt: skip


def own_rise(w: MapWeights, outputs: Sequence[str]) -> MapWeights:
    """``w`` with each of ``outputs`` (where it has an input of its name) read as that
    input's own rise above rest, gain 1, and no other input: m_j = u_j - r_j, plus its
    detail and lift as before (a guided calibration's choice for a face whose readings the
    map's other rows misread: guided/own.py). The others as they were."""
    rows = [j for j, n in enumerate(w.outputs) if n in outputs and n in w.inputs]
    if not rows or not w.config.get("rest", True):
        return w
    a = {k: w.arrays[k].copy() for k in ("a", "b", "c", "w2", "b2")}
    for j in rows:
        for k in a:
            a[k][j] = 0.0
        a["b"][j, w.inputs.index(w.outputs[j])] = 1.0
    return replace(w, arrays={**w.arrays, **a})


def column_setting(key: str, value: Any, default: Any, width: int, top: float = 1.0
                   ) -> float | np.ndarray:  # fmt: skip
    """A per-channel setting of the map (``detail``, ``rest_drift``) checked: a number in [0,
    top], or ``width`` of them (one per column; width 0: a number only); None: ``default``."""
    if value is None:
        return default if isinstance(default, np.ndarray) else float(default)
    v = None
    if isinstance(value, (int, float, list, tuple, np.ndarray)) and not isinstance(value, bool):
        with contextlib.suppress(TypeError, ValueError):  # (ragged lists, text)
            v = np.asarray(value, dtype=np.float64)
    shapes = ((), (width,)) if width else ((),)
    if v is None or v.shape not in shapes or not ((v >= 0) & (v <= top)).all():
        bad = v[~((v >= 0) & (v <= top))] if v is not None and v.ndim == 1 else None
        said = f"{bad[0]:g} on {len(bad)} channels" if bad is not None and len(bad) else \
            repr(value)  # fmt: skip
        raise FacecleanError(f"tracker-map: {key} must be a number within [0, {top:g}], not {said}")
    return float(v) if v.ndim == 0 else v
