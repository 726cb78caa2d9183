"""``faceclean.Cleaner``: the runtime facade other tools code against.

    from faceclean import Cleaner
    c = Cleaner.load()                     # the shipped default cleaner
    y = c.step(x, t)                       # x (M,) in ``c.names`` order, t in seconds
    c = Cleaner.load("model.onnx", streams=64)
    Y = c.step(X, T)                       # X (64, M), T (64,): 64 faces in one call
    cleaned = c.clean(animation)           # a whole clip (resets the streams)

``load`` takes a learned model (.npz checkpoint or exported .onnx step graph), a preset
(file or shipped name) or a method name (``faceclean.filters.METHODS``). Nothing here
imports torch.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from faceclean import filters
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, canonical
from faceclean.errors import FacecleanError

Factory = Callable[[Sequence[str]], filters.Cleaner]
BACKENDS = ("numpy", "onnx")


class Cleaner:
    """A cleaner for ``streams`` faces stepped together, plus whole-clip cleaning.

    ``source`` says what was loaded; ``note`` is set when a fallback was taken (e.g. no
    shipped model yet).
    """

    def __init__(
        self,
        factory: Factory,
        *,
        streams: int = 1,
        names: Sequence[str] = ARKIT52,
        source: str = "",
        note: str | None = None,
    ) -> None:
        if int(streams) < 1:
            raise FacecleanError(f"streams must be >= 1 (got {streams})")
        self.streams = int(streams)
        self.names = tuple(names)
        self.source = source
        self.note = note
        self._factory = factory
        self.cleaner = factory(self.names)  # the streaming filters.Cleaner inside
        self._shape = (len(self.names),) if self.streams == 1 else (self.streams, len(self.names))
        self.reset()

    @classmethod
    def load(
        cls,
        path: str | os.PathLike | None = None,
        *,
        streams: int = 1,
        backend: str | None = None,
        names: Sequence[str] = ARKIT52,
    ) -> Cleaner:
        """Load a cleaner; ``path`` None is the shipped default.

        backend: "numpy" (the torch-free runtime) or "onnx" (ONNX Runtime) for learned
        models; None picks numpy for .npz and onnx for .onnx.
        """
        if backend is not None and backend not in BACKENDS:
            raise FacecleanError(f"unknown backend {backend!r} (known: {', '.join(BACKENDS)})")
        factory, source, note = _resolve(path, backend)
        return cls(factory, streams=streams, names=names, source=source, note=note)

    @property
    def offline(self) -> bool:
        """True for non-causal cleaners (gaussian, savgol): ``clean`` only."""
        return self.cleaner.offline

    @property
    def state_bytes(self) -> int | None:
        """Bytes of state per stream, where the cleaner reports it."""
        return getattr(self.cleaner, "state_bytes", None)

    def reset(self) -> None:
        """Forget every stream's past."""
        self.cleaner.reset()

    def step(self, x: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        """Clean the newest frame: x (M,) and t s, or x (streams, M) and t (streams,)."""
        x = np.asarray(x)
        if x.shape != self._shape:
            raise FacecleanError(f"frame shape {x.shape}, expected {self._shape}")
        if self.streams > 1 and np.shape(t) != (self.streams,):
            raise FacecleanError(f"t shape {np.shape(t)}, expected ({self.streams},)")
        if self.offline:
            raise FacecleanError(f"{self.source} is offline (non-causal): use clean()")
        return self.cleaner.step(x, t)

    def clean(self, anim: Animation) -> Animation:
        """A cleaned copy of a whole clip: its blendshape channels cleaned, every other
        column as it was. Resets the streams."""
        cols = [j for j, n in enumerate(anim.names) if canonical(n) is not None]
        if not cols:
            raise FacecleanError("the animation has no blendshape channels to clean")
        sub = Animation(anim.times, anim.values[:, cols], [anim.names[j] for j in cols])
        cleaned = self._factory(sub.names).clean(sub)
        out = anim.values.copy()
        out[:, cols] = cleaned.values
        self.reset()
        return anim.with_values(out)

    def __repr__(self) -> str:
        return f"Cleaner({self.source!r}, streams={self.streams})"


def build(path: str | os.PathLike, names: Sequence[str]) -> tuple[filters.Cleaner, str]:
    """A learned model file (.npz checkpoint, or .onnx step graph on ONNX Runtime) as a
    cleaner of ``names``, and how to name it."""
    p = Path(path)
    if p.suffix.lower() not in (".npz", ".onnx"):
        raise FacecleanError(f"{p.name}: a model is a .npz or an .onnx file")
    if not p.is_file():
        raise FacecleanError(f"no such model file: {p}")
    factory, what, _ = _learned(p, None)
    return factory(tuple(names)), what


def _resolve(
    path: str | os.PathLike | None, backend: str | None
) -> tuple[Factory, str, str | None]:
    """(factory of filters.Cleaner for given names, description, note)."""
    from faceclean.settings import MODELS

    if path is None or path in ("default", "adaptive", "lstm"):
        # default/adaptive: the shipped default; lstm: the paper's, a shipped baseline
        default = MODELS / ("lstm.npz" if path == "lstm" else "default.npz")
        if default.is_file():
            return _learned(default, backend)
        if path is not None:
            raise FacecleanError(f"no shipped model models/{default.name}; give a model path")
        method = filters.default_method()
        factory, source, _ = _resolve(method, backend)
        return factory, source, f"no shipped model yet (models/default.npz): using {source}"
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in (".npz", ".onnx") or p.is_file():
        if not p.is_file():
            raise FacecleanError(f"no such file: {p}")
        if suffix in (".npz", ".onnx"):
            return _learned(p, backend)
        if suffix == ".json":
            return _classical(str(p), backend)
        raise FacecleanError(f"{p.name}: not a model (.npz, .onnx) nor a preset (.json)")
    return _classical(str(path), backend)


def _learned(path: Path, backend: str | None) -> tuple[Factory, str, None]:
    backend = backend or ("onnx" if path.suffix.lower() == ".onnx" else "numpy")
    if backend == "onnx":
        from faceclean.learned.onnx import OnnxLearned, model_bytes

        graph = model_bytes(path)
        OnnxLearned(graph)  # fail now, with the file's reason, not at the first frame
        return (lambda names: OnnxLearned(graph, names=names)), f"lstm (onnx) {path}", None
    if path.suffix.lower() == ".onnx":
        raise FacecleanError(f"{path.name}: an ONNX graph runs on backend='onnx'")
    from faceclean.learned.adaptive import Adaptive, AdaptiveWeights, is_adaptive
    from faceclean.learned.checkpoint import LSTMWeights
    from faceclean.learned.cleaner import Learned

    if is_adaptive(path):
        adaptive = AdaptiveWeights.load(path)
        factory = lambda names: Adaptive(weights=adaptive, names=names)  # noqa: E731
        return factory, f"adaptive (numpy) {path}", None
    weights = LSTMWeights.load(path)
    return (lambda names: Learned(weights=weights, names=names)), f"lstm (numpy) {path}", None


def _classical(name: str, backend: str | None) -> tuple[Factory, str, None]:
    """A preset (file or shipped name) or a method name with default parameters."""
    from faceclean.filters import presets

    if backend == "onnx":
        raise FacecleanError("the onnx backend runs learned models only")
    if name.lower().endswith(".json") or name in presets.shipped():
        doc = presets.read(name)  # validated once
        return (lambda names: presets.build(doc, names)), f"preset {name}", None
    if name in filters.METHODS:
        filters.cleaner_class(name)  # unknown or unbuildable: fail now
        return (lambda names: filters.make(name, names=names)), f"method {name}", None
    raise FacecleanError(
        f"no model, preset or method named {name!r} "
        f"(methods: {', '.join(filters.METHODS)}; presets: {', '.join(presets.shipped())})"
    )
