"""The runtime benchmark: every cleaner side by side, and the eager-torch reference.

Per cleaner, in one process (the CLI pins it to one core with one BLAS thread):
- latency: per-frame ``step`` time for one stream, p50 and p99 (us);
- throughput: stream-frames per second with S streams stepped together (S = 1, 64, 1024),
  the best of many ~2 ms blocks (the machine may be shared);
- hour: seconds to clean one hour of 60 fps animation offline (``clean``), measured on a
  20 s clip (best of 5) and scaled linearly (the cost per frame is constant), said so;
- state: bytes of per-stream state the cleaner holds (all per-stream arrays).
The references are eager PyTorch on the same weights (faceclean.neural.reference: the
paper's LSTM, the shipped default's adaptive network with its core run, FC and GBT;
faceclean.neural.map_reference: the shipped MediaPipe map); every figure also appears as
a cost ratio to the reference on the same network (the row's ``ref``): our time / its
time (< 1 is faster). Without torch our rows run alone and the result says why
(``references``).
Inputs are a seeded random walk in [0, 1] at 60 fps; speed does not depend on values.
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52

FPS = 60.0  # Hz
HOUR = 3600.0  # s
BLOCK_S = 0.002  # s, length of one timed block of steps (under a scheduler slice)


@dataclass
class Sizes:
    """How much to measure (``quick`` is for smoke tests: seconds, not accuracy)."""

    streams: tuple[int, ...] = (1, 64, 1024)
    latency_steps: int = 3000
    target_s: float = 0.5  # s of measuring per throughput figure
    clip_s: float = 20.0  # s of 60 fps animation cleaned, then scaled to an hour
    repeats: int = 5  # at least this many timed blocks, and cleans of the clip; best counts

    @classmethod
    def quick(cls, streams: tuple[int, ...] = (1, 4)) -> Sizes:
        return cls(streams=streams, latency_steps=20, target_s=0.0, clip_s=0.5, repeats=1)


@dataclass
class Row:
    name: str
    p50_us: float | None = None
    p99_us: float | None = None
    throughput: dict[int, float] = field(default_factory=dict)  # streams -> frames/s
    hour_s: float | None = None
    state_bytes: int | None = None
    note: str = ""
    ref: str = "reference"  # the row its ratios are to: eager torch on the same network
    key: str = ""  # a reference row's own name for ``ref``


def _walk(n: int, S: int, seed: int) -> np.ndarray:
    """(n, S, 52) random-walk frames in [0, 1]."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(0.0, 0.01, (n, S, 52)).astype(np.float64)
    return np.clip(0.3 + np.cumsum(steps, axis=0), 0.0, 1.0)


def _times(n: int, S: int, start: int = 0) -> np.ndarray:
    """(n, S) s: 60 fps, the streams a little out of phase."""
    return (np.arange(start, start + n)[:, None] + np.linspace(0, 0.5, S)[None]) / FPS


class _Stepper:
    """The one interface the timing loops need: ``begin(S, x0, t0)``, ``step(x, t)``."""

    def __init__(self, make: Callable[[], Any], reference: bool = False) -> None:
        self.make, self.reference = make, reference
        self.cleaner: Any = None
        self.t_last: np.ndarray | None = None

    def begin(self, x0: np.ndarray, t0: np.ndarray) -> None:
        self.cleaner = self.make()
        if self.reference:
            self.cleaner.start(x0)
            self.t_last = t0
        else:
            self.cleaner.step(x0[0] if len(x0) == 1 else x0, t0[0] if len(t0) == 1 else t0)

    def step(self, x: np.ndarray, t: np.ndarray) -> None:
        if self.reference:
            self.cleaner.step(x, t - self.t_last)
            self.t_last = t
        elif len(x) == 1:
            self.cleaner.step(x[0], float(t[0]))
        else:
            self.cleaner.step(x, t)


def _latency(st: _Stepper, n: int) -> tuple[float, float]:
    x, t = _walk(n + 21, 1, 1), _times(n + 21, 1)
    st.begin(x[0], t[0])
    for i in range(1, 21):  # warm (compiles, caches)
        st.step(x[i], t[i])
    clock = time.perf_counter_ns
    dts = np.empty(n)
    for i in range(n):
        t0 = clock()
        st.step(x[i + 21], t[i + 21])
        dts[i] = clock() - t0
    return float(np.percentile(dts, 50) / 1e3), float(np.percentile(dts, 99) / 1e3)


def _throughputs(steppers: dict[str, _Stepper], S: int, sizes: Sizes) -> dict[str, float]:
    """Stream-frames per second of every stepper with S streams: the best block.

    Blocks of about BLOCK_S, taken round-robin across the cleaners, best of many (as
    timeit's min): on a shared machine a block the scheduler did not interrupt measures
    the code, and neighbours weigh on every cleaner alike.
    """
    plan, probes = {}, 8  # frames of the probe; the timed frames come after them
    for name, st in steppers.items():
        probe, t = _walk(probes, S, 2), _times(probes, S)
        st.begin(probe[0], t[0])
        per_step = np.inf  # s; the fastest of 4 steps after 3 that warm (a first call
        for i in range(1, probes):  # may load a compiled kernel: too few steps a block)
            t0 = time.perf_counter()
            st.step(probe[i], t[i])
            per_step = min(per_step, time.perf_counter() - t0) if i > 3 else per_step
        per_step = max(per_step, 1e-7)
        plan[name] = (int(min(max(BLOCK_S / per_step, 1), 5000)), per_step)  # steps/block
    round_s = sum(n * p for n, p in plan.values())
    blocks = int(min(max(sizes.target_s * len(plan) / round_s, sizes.repeats), 200))
    data = {
        name: (_walk(n * blocks, S, 3), _times(n * blocks, S, probes))
        for name, (n, _) in plan.items()
    }
    best = dict.fromkeys(steppers, 0.0)
    for r in range(blocks):
        for name, st in steppers.items():
            n, (x, t) = plan[name][0], data[name]
            t0 = time.perf_counter()
            for i in range(r * n, (r + 1) * n):
                st.step(x[i], t[i])
            best[name] = max(best[name], S * n / (time.perf_counter() - t0))
    return best


def _hours(cleans: dict[str, Callable[[Animation], Any]], sizes: Sizes) -> dict[str, float]:
    """Seconds to clean one hour of 60 fps, per cleaner: the best of several cleans of a
    clip_s clip (round-robin across the cleaners), scaled to an hour."""
    n = int(sizes.clip_s * FPS)
    anim = Animation.from_arkit(np.arange(n) / FPS, _walk(n, 1, 4)[:, 0])
    best = dict.fromkeys(cleans, np.inf)
    for r in range(sizes.repeats):
        for name, clean in cleans.items():
            if r == 0:
                clean(Animation.from_arkit(anim.times[:30], anim.values[:30]))  # warm
            t0 = time.perf_counter()
            clean(anim)
            best[name] = min(best[name], time.perf_counter() - t0)
    return {name: float(b * HOUR / sizes.clip_s) for name, b in best.items()}


def _state_bytes(cleaner: Any, S: int) -> int:
    """Bytes per stream of the state a stepped cleaner keeps: its recurrent state plus
    the last output and time every StreamCleaner holds (scratch buffers not counted)."""
    kept = (cleaner._y.nbytes + cleaner._t.nbytes) // S
    if hasattr(cleaner, "state_bytes"):  # the learned runtimes report theirs
        return int(cleaner.state_bytes + kept)
    if getattr(cleaner, "_state", None) is None:  # a step of its own (the tracker map):
        held = [a for a in vars(cleaner).values() if isinstance(a, np.ndarray)]  # every
        for part in vars(cleaner).values():  # and its parts' (the band's noise state)
            if hasattr(part, "__dict__") and not callable(part):
                held += [a for a in vars(part).values() if isinstance(a, np.ndarray)]
        return int(sum(a.nbytes for a in held if a.ndim and len(a) == S) // S)  # row/stream
    return int(sum(a.nbytes for a in cleaner._state) // S + kept)


def _reference_clean(make: Callable[[], Any]) -> Callable[[Animation], None]:
    """The reference's offline clean: start, then step every frame."""

    def clean(anim: Animation) -> None:
        ref, x, dt = make(), anim.values[:, None], np.diff(anim.times)[:, None]
        ref.start(x[0])
        for i in range(1, len(x)):
            ref.step(x[i], dt[i - 1])

    return clean


MAP = "tracker map (mediapipe)"  # the row of the MediaPipe cleaner


def tracker_map() -> Any:
    """The MediaPipe cleaner as ``faceclean clean --tracker mediapipe`` builds it for an
    ARKit take: the shipped map (models/mediapipe.npz) on the 52 ARKit columns."""
    from faceclean.resolve import resolve, tracker_words

    return resolve(tracker_words("mediapipe")).build(ARKIT52)


def cleaners(model: Any) -> dict[str, tuple[Callable[[], Any], str]]:
    """name -> (factory, note) for every streaming cleaner benchmarked."""
    from faceclean.filters import make, presets
    from faceclean.learned import jit
    from faceclean.learned.lstm import Learned

    out: dict[str, tuple[Callable[[], Any], str]] = {}
    for name in ("ema", "one-euro", "kalman"):
        if name in presets.shipped():
            out[name] = (lambda n=name: presets.build(n), "shipped preset")
        else:
            out[name] = (lambda n=name: make(n), "default parameters")
    if jit.available():
        out["lstm"] = (
            lambda: Learned(weights=model),
            f"numba kernel <= {Learned.jit_max_streams} streams, numpy + compiled gates above",
        )
    out["lstm-numpy"] = (lambda: Learned(weights=model, kernel="numpy"), "numpy + BLAS only")
    from faceclean.learned.adaptive import Adaptive, AdaptiveWeights
    from faceclean.settings import MODELS

    default = AdaptiveWeights.load(MODELS / "default.npz")
    kind = "inert network: One Euro form" if Adaptive(weights=default).inert else "GRU core"
    out["default (adaptive)"] = (lambda: Adaptive(weights=default), f"shipped; {kind}, numpy")
    fc = "shipped FC baseline, numpy (numba features and blend from 2 streams)"
    gbt = "shipped GBT, numba trees a step when installed"
    for name, note in (("fc", fc), ("gbt", gbt)):
        out[name] = (lambda n=name: make(n), note)
    out[MAP] = (tracker_map, "shipped, `clean --tracker mediapipe`, numpy")
    try:
        from faceclean.learned.export import build
        from faceclean.learned.onnx import OnnxLearned

        graph = build(model).SerializeToString()
        out["lstm-onnx"] = (lambda: OnnxLearned(graph), "onnxruntime, 1 thread")
    except Exception as e:  # onnx or onnxruntime missing: say so in the table
        out["lstm-onnx"] = (None, f"skipped: {str(e).splitlines()[0]}")
    return out


def run(
    sizes: Sizes | None = None,
    model_path: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Measure everything; returns a JSON-ready dict (machine, model, rows, reference)."""
    from faceclean.filters import make
    from faceclean.learned.checkpoint import LSTMWeights
    from faceclean.learned.lstm import default_model_path

    sizes = sizes or Sizes()
    say = progress or (lambda s: None)
    path = model_path or (str(default_model_path()) if default_model_path().is_file() else None)
    model = LSTMWeights.load(path) if path else LSTMWeights.random(ARKIT52, seed=0)
    model_note = path or "random init (no shipped model yet): same architecture, same cost"

    rows: dict[str, Row] = {}
    steppers: dict[str, _Stepper] = {}
    cleans: dict[str, Callable[[Animation], Any]] = {}
    for name, (factory, note) in cleaners(model).items():
        rows[name] = Row(name, note=note)
        if factory is not None:
            steppers[name] = _Stepper(factory)
            cleans[name] = lambda a, f=factory: f().clean(a)
    for name in ("gaussian", "savgol"):
        rows[name] = Row(name, note="offline, default parameters")
        cleans[name] = make(name).clean
    reference, skipped = None, None
    try:
        from faceclean.neural.reference import single_thread
    except ImportError as e:  # our rows run alone; the result says why
        skipped = f"eager torch references not run: {e} (pip install 'faceclean[neural]')"
    else:
        from faceclean.neural.reference import NaiveReference

        reference = Row(NaiveReference.name, note=f"torch {single_thread()}, 1 thread")
        steppers["reference"] = _Stepper(lambda: NaiveReference(model), reference=True)
        cleans["reference"] = _reference_clean(lambda: NaiveReference(model))
        for key, (ours, make_ref, note) in _references().items():
            probe = make_ref()
            rows[key] = Row(probe.name, note=note)
            rows[key].ref = rows[key].key = rows[ours].ref = key
            steppers[key] = _Stepper(make_ref, reference=True)
            cleans[key] = _reference_clean(make_ref)
    row_of = dict(rows, reference=reference)

    for name, st in steppers.items():
        say(f"latency: {name}")
        row_of[name].p50_us, row_of[name].p99_us = _latency(st, sizes.latency_steps)
    for n in sizes.streams:
        say(f"throughput: {n} streams")
        for name, value in _throughputs(steppers, n, sizes).items():
            row_of[name].throughput[n] = value
    last = sizes.streams[-1]  # the cleaners now hold this many streams
    for name, st in steppers.items():
        ref_bytes = st.cleaner.state_bytes if st.reference else None
        row_of[name].state_bytes = ref_bytes or _state_bytes(st.cleaner, last)
    say("one hour")
    for name, value in _hours(cleans, sizes).items():
        row_of[name].hour_s = value
    return {
        "machine": machine(),
        "model": {"source": model_note, "layers": model.layers, "hidden": model.hidden},
        "sizes": asdict(sizes),
        "rows": [asdict(r) for r in rows.values()],
        "reference": asdict(reference) if reference else None,
        "references": skipped or "eager torch, one thread, in this run",
        "hour_extrapolated_from_s": sizes.clip_s,
    }


def _references() -> dict[str, tuple[str, Callable[[], Any], str]]:
    """The references besides the LSTM's: key -> (our row, factory, note). Needs torch."""
    from faceclean.filters import make
    from faceclean.learned.adaptive import AdaptiveWeights
    from faceclean.neural.map_reference import MapReference
    from faceclean.neural.reference import AdaptiveReference, DerivativeReference
    from faceclean.settings import MODELS

    default = AdaptiveWeights.load(MODELS / "default.npz")
    return {
        "reference-adaptive": (
            "default (adaptive)",
            lambda: AdaptiveReference(default),
            "the default's network, core run",
        ),
        **{
            f"reference-{base}": (
                base,
                lambda b=base: DerivativeReference(make(b)),
                f"the shipped {base}'s model, float64",
            )
            for base in ("fc", "gbt")
        },
        "reference-map": (MAP, lambda: MapReference(tracker_map()), "the shipped map, float64"),
    }


def machine() -> dict[str, Any]:
    """CPU model, cores usable, Python and library versions, BLAS, load."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if "model name" in ln), cpu)
    except OSError:
        pass
    info: dict[str, Any] = {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "pinned_to": sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None,
        "env": {
            k: os.environ.get(k)
            for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OPENBLAS_CORETYPE")
        },
    }
    try:
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        info["blas"] = f"{blas.get('name')} {blas.get('version')}"
    except Exception:  # the config layout differs across numpy versions
        info["blas"] = "unknown"
    for mod in ("numba", "onnxruntime", "torch"):
        try:
            info[mod] = __import__(mod).__version__
        except ImportError:
            info[mod] = None
    from faceclean.filters import compiled

    info["whole_take"] = compiled.status()  # a long take's clean: compiled, or numpy (slower)
    return info
