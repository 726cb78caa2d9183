"""The shipped MediaPipe map's step with its smoothed, climbing rest (ninth and nineteenth
rounds) against the same map with a blink lift (its low-pass of the raw input, twenty-second
round; the shipped map has none), with no climb and on the plain running minimum, side by
side in one run, one core.

    taskset -c 1 .venv/bin/python benchmarks/rest_cost.py

Median step time per stream-frame, one stream (3000 frames) and 1024 (300 frames), three
rounds each: the price of the lift, of the rest's smoothing and of its climb
(docs/BENCHMARKS.md).
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

    def without(*keys: str) -> MapWeights:
        return replace(w, config={k: v for k, v in w.config.items() if k not in keys})

    eyes = [j for j, name in enumerate(w.outputs) if name.startswith("eyeBlink")]
    gain, knee = np.zeros(len(w.outputs)), np.zeros(len(w.outputs))
    gain[eyes], knee[eyes] = 3.0, 0.1
    lifted = replace(w, arrays=dict(w.arrays, lift_gain=gain, lift_knee=knee))
    still, plain = without("rest_drift"), without("rest_tau", "rest_warm", "rest_drift")
    rng = np.random.default_rng(0)
    for s, n in ((1, 3000), (1024, 300)):
        for rnd in range(3):
            d, a, b, c = (median_step(m, s, n, rng) / s * 1e6 for m in (lifted, w, still, plain))
            print(f"{s} streams, round {rnd}: shipped {a:.3f} us a stream-frame, "
                  f"lifted {d:.3f}, no climb {b:.3f}, plain {c:.3f}; lift {d / a:.3f}x, "
                  f"climb {a / b:.3f}x, smoothing {b / c:.3f}x")  # fmt: skip


if __name__ == "__main__":
    main()
