"""One live stream: the learned cleaners' step against eager PyTorch, side by side.

    .venv/bin/python benchmarks/live_step.py [--steps 3000] [--rounds 5]

Per round, each stepper cleans the same 60 fps stream of ``--steps`` frames, one frame
a call, in turn (interleaved, so a busy neighbour weighs on all alike); the p50 of the
per-call times of every round is reported, and its ratio to the eager torch reference
(``faceclean.neural.reference.NaiveReference``, one thread) of the same round. The
LSTM runs its numba kernel (loaded with learned/jit.py when numba is installed) and
its numpy kernel; the MediaPipe tracker map its numpy step (its arithmetic is under
1 us; the rest is numpy's per-call cost).
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
    from faceclean.filters import make
    from faceclean.learned.checkpoint import LSTMWeights
    from faceclean.neural.reference import NaiveReference, single_thread
    from faceclean.settings import MODELS

    single_thread()
    weights = LSTMWeights.load(MODELS / "lstm.npz")
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

    def torch_ref():
        r = NaiveReference(weights)
        r.start(x[:1])
        out = []
        for i in range(1, n):
            a = time.perf_counter_ns()
            r.step(x[i : i + 1], dt)
            out.append(time.perf_counter_ns() - a)
        return out

    runs = {
        "torch (eager, LSTM)": torch_ref,
        "lstm (numba kernel)": ours(lambda: make("lstm", {"kernel": "numba"}, names=ARKIT52)),
        "lstm (numpy kernel)": ours(lambda: make("lstm", {"kernel": "numpy"}, names=ARKIT52)),
        "tracker map (MediaPipe)": ours(
            lambda: make("tracker-map", {"model": MODELS / "mediapipe.npz"}, names=ARKIT52)
        ),
        "default (adaptive, inert)": ours(lambda: make("adaptive", {}, names=ARKIT52)),
    }
    p50: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(args.rounds):
        for name, run in runs.items():
            p50[name].append(statistics.median(run()) / 1e3)  # us
    print(f"{args.rounds} rounds of {n} steps, one stream; load average "
          f"{os.getloadavg()[0]:.2f}\n")  # fmt: skip
    print("| stepper | p50 per step (us), median of rounds | ratio to torch, each round |")
    print("|---|---|---|")
    ref = p50["torch (eager, LSTM)"]
    for name, v in p50.items():
        ratios = ", ".join(f"{a / b:.2f}" for a, b in zip(v, ref, strict=True))
        print(f"| {name} | {statistics.median(v):.1f} | {ratios} |")


if __name__ == "__main__":
    main()
