"""The shipped MediaPipe map's step with its smoothed rest (ninth round) against the same
map on the plain running minimum, side by side in one run, one core.

    taskset -c 1 .venv/bin/python benchmarks/rest_cost.py

Median step time per stream-frame, one stream (3000 frames) and 1024 (300 frames), three
rounds each: the price of the rest's smoothing (docs/BENCHMARKS.md).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from faceclean.learned.map_weights import MapWeights
from faceclean.learned.tracker_map import TrackerMap
from faceclean.settings import MODELS
from faceclean.trackers.mediapipe import NAMES


def median_step(weights: MapWeights, s: int, n: int, rng) -> float:
    """Median seconds of one ``step`` of ``s`` streams (uniform frames at 30 fps)."""
    tm = TrackerMap(weights=weights, names=NAMES)
    x = rng.uniform(0, 1, (n, s, len(NAMES)) if s > 1 else (n, len(NAMES)))
    for k in range(20):  # past the rest's warm-up: the usual frame
        tm.step(x[k], k / 30.0)
    times = []
    for k in range(20, n):
        a = time.perf_counter()
        tm.step(x[k], k / 30.0)
        times.append(time.perf_counter() - a)
    return float(np.median(times))


def main() -> None:
    w = MapWeights.load(MODELS / "mediapipe.npz")
    keys = ("rest_tau", "rest_warm")
    plain = replace(w, config={k: v for k, v in w.config.items() if k not in keys})
    rng = np.random.default_rng(0)
    for s, n in ((1, 3000), (1024, 300)):
        for rnd in range(3):
            a, b = median_step(w, s, n, rng), median_step(plain, s, n, rng)
            print(f"{s} streams, round {rnd}: smoothed {a / s * 1e6:.3f} us a stream-frame, "
                  f"plain {b / s * 1e6:.3f}, ratio {a / b:.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
