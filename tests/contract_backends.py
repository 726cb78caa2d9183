"""Every runnable cleaner backend the contract suite (test_contract.py) runs, in one table.

A backend is one way to get a cleaner: a method by name (``filters.make``; the learned
ones with their shipped models), the LSTM with each kernel forced, ONNX Runtime on a graph
exported from the shipped LSTM, and the ``faceclean.Cleaner`` facade (a preset file, a
method with overrides, model files). A backend that does not keep a clause of the
contract declares it in ``unsupported`` with the reason; the suite skips that clause for
that backend alone and prints the reason.
"""

from __future__ import annotations

import functools
import importlib.util
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from faceclean.filters import METHODS, make
from faceclean.settings import MODELS, PRESETS

# Every clause of the contract (filters/base.py), by the name a test marks itself with.
CLAUSES = {
    "constant": "constant in gives constant out (learned: a held face settles)",
    "rate": "the same curve at 30, 60 and 120 fps agrees",
    "any_dt": "finite, bounded output for any dt",
    "t_zero": "t = 0.0 is a valid first time",
    "missing": "missing frames stay missing and change nothing",
    "names": "clean keeps times, names and meta, and leaves its input unchanged",
    "order": "the channels in another order give the same per-channel output",
    "clean_rules": "clean: an older or repeated time repeats the last output; NaN channels",
    "step_kind": "a stream's first step returns the frame; an offline step refuses",
    "causal": "the output never depends on later frames",
    "reset": "reset forgets everything",
    "batch": "clean equals reset-then-step",
    "streams": "(S, M) frames with t (S,) equal S independent cleaners",
    "time_rules": "step: missing frames, NaN channels, repeats, gaps (filters/base.py)",
    "whole_take": "a long take's clean (compiled, filters/compiled.py) equals reset-then-step",
}
STREAMING = ("causal", "reset", "batch", "streams", "time_rules", "whole_take")
# The methods whose whole-take clean runs filters/compiled.py's kernels (the LSTM's is
# learned/jit.py's ``run``, whatever the take's length: the batch clause proves it).
COMPILED = {"one-euro", "ema", "kalman", "adaptive", "tracker-map"}
# The tracker map's whole take sums its products in the kernel's order, not BLAS's
# (measured 1.2e-15 on an hour of 60 fps).
WHOLE_TOL = {"tracker-map": 1e-12}
OFFLINE = "offline (non-causal): clean(animation) only, step refuses"

# Same-curve-at-any-rate tolerance: max |difference| (weight units) at shared instants,
# for a curve of amplitude <= 0.3 and frequencies <= 1.1 Hz, at default parameters.
# A causal filter fed sampled input lags about half a frame more at 30 fps than at
# 120 fps (EMA measured 0.017); One Euro's published smoothing factor
# 1 / (1 + 1 / (2 pi fc dt)) is not rate-exact (measured 0.031); Kalman's exact
# discretisation (3e-3) and the time-domain offline kernels (2e-4) nearly are.
RATE_TOL = {"one-euro": 0.05, "rotation": 0.05, "kalman": 0.01, "gaussian": 0.005, "savgol": 0.005}
RATE_TOL_DEFAULT = 0.03
LEARNED = {"lstm", "fc", "gbt", "adaptive"}
# (S, M) frames equal S cleaners to float64 rounding, but for the numpy LSTM kernel: its float32
# BLAS product over S columns rounds unlike the one-column product (measured 1.8e-7 over
# 90 frames; tests/test_runtime.py states 1e-6 for the runtimes), and FC's float32 layers.
BLAS_STREAMS_TOL = 1e-6
ONNX = ("onnx", "onnxruntime")  # export needs onnx, the runtime onnxruntime


class Files:
    """Files some backends need, made once per session in ``folder``."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder

    @functools.cached_property
    def onnx(self) -> Path:
        """The shipped LSTM (models/lstm.npz) exported as an ONNX step graph."""
        from faceclean.learned.export import export

        path = self.folder / "lstm.onnx"
        export(MODELS / "lstm.npz", path)
        return path


Make = Callable[[Files, tuple[str, ...], int], Any]  # (files, names, streams) -> a cleaner


@dataclass(frozen=True)
class Backend:
    id: str
    method: str  # the filters.METHODS name it runs
    kind: str  # "method", "kernel", "onnx" or "facade"
    make: Make = field(repr=False)
    offline: bool = False
    unsupported: Mapping[str, str] = field(default_factory=dict)  # clause -> reason
    needs: tuple[str, ...] = ()  # optional packages it runs on (absent: every test skips)
    streams_tol: float = 1e-12  # (S, M) frames vs S cleaners, max |difference|

    @property
    def whole_tol(self) -> float:
        """A long take's clean vs reset-then-step, max |difference| (0: the same bits)."""
        return WHOLE_TOL.get(self.method, 0.0)

    @property
    def face(self) -> bool:
        """Learned: trained on faces, so it gets the face-shaped contracts."""
        return self.method in LEARNED

    @property
    def rate_tol(self) -> float:
        return RATE_TOL.get(self.method, RATE_TOL_DEFAULT)

    def absent(self) -> str | None:
        """Why it cannot run here (an optional package missing), else None."""
        missing = [p for p in self.needs if importlib.util.find_spec(p) is None]
        return f"{', '.join(missing)} not installed" if missing else None

    def skips(self) -> dict[str, str]:
        """Clause -> why this backend does not keep it."""
        own = {c: OFFLINE for c in STREAMING} if self.offline else {}
        return {**own, **self.unsupported}


def _method(method: str, **params: Any) -> Make:
    return lambda files, names, streams: make(method, params, names=names)


def _facade(words: Callable[[Files], str | None], *settings: str) -> Make:
    def build(files: Files, names: tuple[str, ...], streams: int) -> Any:
        from faceclean import Cleaner

        return Cleaner.load(words(files), settings=list(settings), names=names, streams=streams)

    return build


def _onnx(files: Files, names: tuple[str, ...], streams: int) -> Any:
    from faceclean.learned.onnx import OnnxLearned

    return OnnxLearned(files.onnx, names=names)


def _offline(method: str) -> bool:
    from faceclean.filters import cleaner_class

    return bool(cleaner_class(method).offline)


BACKENDS: list[Backend] = [
    *(
        Backend(
            m,
            m,
            "method",
            _method(m),
            offline=_offline(m),
            # FC's float32 layers (issue 19: half the bytes): the LSTM kernel's BLAS rounding
            streams_tol=BLAS_STREAMS_TOL if m == "fc" else Backend.streams_tol,
        )  # fmt: skip
        for m in METHODS
        if m not in ("lstm", "tracker-map")  # the LSTM runs once per kernel; the map, below
    ),
    Backend(
        "lstm[numpy]",
        "lstm",
        "kernel",
        _method("lstm", kernel="numpy"),
        streams_tol=BLAS_STREAMS_TOL,
    ),
    Backend("lstm[numba]", "lstm", "kernel", _method("lstm", kernel="numba"), needs=("numba",)),
    Backend(
        "tracker-map[mediapipe.npz]",
        "tracker-map",
        "method",
        _method("tracker-map", model=MODELS / "mediapipe.npz"),
        unsupported={
            c: "a tracker map changes levels by design: its first and held outputs are the "
            "mapped input, not the input (its own rules: tests/learned/test_tracker_map.py)"
            for c in ("constant", "t_zero", "step_kind", "time_rules")
        },
    ),
    Backend("lstm[onnx]", "lstm", "onnx", _onnx, needs=ONNX),
    Backend(
        "Cleaner.load(preset)",
        "one-euro",
        "facade",
        _facade(lambda f: str(PRESETS / "one-euro.json")),
    ),
    Backend(
        "Cleaner.load(kalman+settings)",
        "kalman",
        "facade",
        _facade(lambda f: "kalman", "q=8", "eyes.r=0.01", "jawOpen.q=20"),
    ),
    Backend("Cleaner.load()", "adaptive", "facade", _facade(lambda f: None)),  # default.npz
    Backend(
        "Cleaner.load(lstm.npz)", "lstm", "facade", _facade(lambda f: str(MODELS / "lstm.npz"))
    ),
    Backend(
        "Cleaner.load(lstm.onnx)", "lstm", "facade", _facade(lambda f: str(f.onnx)), needs=ONNX
    ),
]
