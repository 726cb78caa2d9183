"""One live stream: the learned cleaners' step against eager PyTorch, side by side.

    .venv/bin/python benchmarks/live_step.py [--steps 3000] [--rounds 5]

Per round, each stepper cleans the same 60 fps stream of ``--steps`` frames, one frame
a call, in turn (interleaved, so a busy neighbour weighs on all alike); the p50 of the
per-call times of every round is reported, and its ratio to eager torch on its own
network in the same round (one thread): the LSTM's ``NaiveReference``, FC's
``DerivativeReference``, the default's ``AdaptiveReference``, the MediaPipe map's
``MapReference`` (faceclean.neural). The
LSTM runs its numba kernel (loaded with learned/jit.py when numba is installed) and
its numpy kernel; FC and the MediaPipe tracker map (as ``faceclean bench`` builds it)
their numpy steps.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    from faceclean.channels import ARKIT52
    from faceclean.evaluation.bench import tracker_map
    from faceclean.filters import make
    from faceclean.learned.adaptive import AdaptiveWeights
    from faceclean.learned.checkpoint import LSTMWeights
    from faceclean.neural.map_reference import MapReference
    from faceclean.neural.reference import (
        AdaptiveReference,
        DerivativeReference,
        NaiveReference,
        single_thread,
    )
    from faceclean.settings import MODELS

    single_thread()
    weights = LSTMWeights.load(MODELS / "lstm.npz")
    default = AdaptiveWeights.load(MODELS / "default.npz")
    rng = np.random.default_rng(0)
    n = args.steps
    t = np.arange(n) / 60.0
    x = np.clip(0.4 + 0.1 * rng.standard_normal((n, 52)), 0, 1)
    dt = np.full((1,), 1 / 60, np.float32)

    def ours(build):
        def run():
            c = build()
            c.step(x[0], t[0])
            out = []
            for i in range(1, n):
                a = time.perf_counter_ns()
                c.step(x[i], t[i])
                out.append(time.perf_counter_ns() - a)
            return out

        return run

    def torch_ref(build):
        def run():
            r = build()
            r.start(x[:1])
            out = []
            for i in range(1, n):
                a = time.perf_counter_ns()
                r.step(x[i : i + 1], dt)
                out.append(time.perf_counter_ns() - a)
            return out

        return run

    lstm = "torch (eager, LSTM)"
    runs = {  # name -> (run, the name of its reference)
        lstm: (torch_ref(lambda: NaiveReference(weights)), lstm),
        "lstm (numba kernel)": (
            ours(lambda: make("lstm", {"kernel": "numba"}, names=ARKIT52)),
            lstm,
        ),
        "lstm (numpy kernel)": (
            ours(lambda: make("lstm", {"kernel": "numpy"}, names=ARKIT52)),
            lstm,
        ),
        "torch (eager, FC)": (torch_ref(lambda: DerivativeReference(make("fc"))), None),
        "fc": (ours(lambda: make("fc", names=ARKIT52)), "torch (eager, FC)"),
        "torch (eager, map)": (torch_ref(lambda: MapReference(tracker_map())), None),
        "tracker map (MediaPipe)": (ours(tracker_map), "torch (eager, map)"),
        "torch (eager, adaptive)": (torch_ref(lambda: AdaptiveReference(default)), None),
        "default (adaptive, inert)": (
            ours(lambda: make("adaptive", {}, names=ARKIT52)),
            "torch (eager, adaptive)",
        ),
    }
    p50: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(args.rounds):
        for name, (run, _ref) in runs.items():
            p50[name].append(statistics.median(run()) / 1e3)  # us
    print(f"{args.rounds} rounds of {n} steps, one stream; load average "
          f"{os.getloadavg()[0]:.2f}\n")  # fmt: skip
    print("| stepper | p50 per step (us), median of rounds | ratio to its torch, each round |")
    print("|---|---|---|")
    for name, v in p50.items():
        ref = p50[runs[name][1] or name]
        ratios = ", ".join(f"{a / b:.2f}" for a, b in zip(v, ref, strict=True))
        print(f"| {name} | {statistics.median(v):.1f} | {ratios} ({runs[name][1] or name}) |")


if __name__ == "__main__":
    main()
