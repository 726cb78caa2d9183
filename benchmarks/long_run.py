"""Ten million frames through the default cleaner: no NaN, no drift, flat memory.

    .venv/bin/python benchmarks/long_run.py                  # 1,000 streams x 10,000 frames
    .venv/bin/python benchmarks/long_run.py --model m.npz    # any model, preset or method

The frames go through ``faceclean.Cleaner.load(MODEL, streams=S)`` (the shipped learned
model when there is one, else the documented fallback), S streams stepped together in
one call per time step: S x N frames in N calls. Four kinds of stream, a quarter each:

- constant: a fixed face at a jittered 60 fps; the output must settle and stay put
  (drift = how much it still moves over the last WINDOW steps);
- periodic: a sum of sines at exactly 60 fps; the output must repeat with the input's
  period (drift = largest difference between the last period and one DRIFT_GAP periods
  earlier);
- noisy: a random walk with tracker noise, tracking-loss frames and a 2 s silence every
  ~50 s; the output must stay finite and inside [-0.5, 1.5];
- hostile: the noisy stream plus repeated and backwards timestamps, NaN cells and absurd
  values (1e300).

Memory: RSS (/proc/self/status) and tracemalloc's current size, sampled every
SAMPLE steps; flat means the last sample is within a few MiB of the one at 10 %.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

from faceclean import Cleaner

M = 52
FPS = 60.0  # Hz
PERIOD = 120  # frames (2 s) of the periodic streams
WINDOW = 1000  # steps over which the constant streams must not move
DRIFT_GAP = 20  # periods between the two compared periods
SAMPLE = 500  # steps between memory samples


def rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class Streams:
    """The four kinds of input, generated one time step at a time for S streams."""

    def __init__(self, streams: int, seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)
        S = streams
        self.kind = np.arange(S) % 4  # 0 constant, 1 periodic, 2 noisy, 3 hostile
        self.level = self.rng.uniform(0.05, 0.95, (S, M))  # constant faces
        self.amp = self.rng.uniform(0.05, 0.3, (S, M))
        self.harm = self.rng.integers(1, 4, (S, M))  # harmonics of the period
        self.phase = self.rng.uniform(0, 2 * np.pi, (S, M))
        self.walk = self.rng.uniform(0.2, 0.8, (S, M))
        self.t = np.zeros(S)  # s, the latest time sent per stream
        self.n = 0

    def next(self) -> tuple[np.ndarray, np.ndarray]:
        """(S, M) frames and (S,) times of step n."""
        rng, S, n = self.rng, len(self.kind), self.n
        self.n += 1
        x = np.empty((S, M))
        t = self.t + rng.uniform(0.8, 1.2, S) / FPS  # jittered 60 fps
        const, per = self.kind == 0, self.kind == 1
        x[const] = self.level[const]
        t[per] = n / FPS  # exact timing: the output must be periodic too
        w = 2 * np.pi * self.harm[per] / PERIOD
        x[per] = 0.5 + self.amp[per] * np.sin(w * n + self.phase[per])
        noisy = self.kind >= 2
        self.walk[noisy] = np.clip(self.walk[noisy] + rng.normal(0, 0.01, (noisy.sum(), M)), 0, 1)
        x[noisy] = self.walk[noisy] + rng.normal(0, 0.02, (noisy.sum(), M))
        x[noisy & (rng.random(S) < 0.01)] = np.nan  # tracking loss
        silence = noisy & (rng.random(S) < 1 / 3000)  # ~every 50 s: 2 s without a face
        t[silence] += 2.0
        hostile = self.kind == 3
        h = np.flatnonzero(hostile)
        r = rng.random(len(h))
        t[h[r < 0.01]] = self.t[h[r < 0.01]]  # repeated time
        back = h[(r >= 0.01) & (r < 0.02)]
        t[back] = self.t[back] - 0.05  # backwards
        cells = rng.random((len(h), M))
        xh = x[h]
        xh[cells < 0.005] = np.nan
        xh[(cells >= 0.005) & (cells < 0.006)] = 1e300
        x[h] = xh
        self.t = np.maximum(self.t, t)
        return x, t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", help="model, preset or method (default: the shipped default)")
    ap.add_argument("--streams", type=int, default=1000)
    ap.add_argument("--frames", type=int, default=10_000, help="per stream")
    ap.add_argument("--json", help="write the figures here")
    ap.add_argument(
        "--random-lstm", action="store_true", help="an untrained LSTM (H 128, 2 layers) as model"
    )
    args = ap.parse_args()
    S, N = args.streams, args.frames

    with tempfile.TemporaryDirectory() as folder:
        model = args.model
        if args.random_lstm:  # the learned runtime before a trained model ships
            from faceclean.channels import ARKIT52
            from faceclean.learned.checkpoint import LSTMWeights

            model = str(Path(folder) / "random.npz")
            LSTMWeights.random(ARKIT52, hidden=128, layers=2, seed=0).save(model)
        cleaner = Cleaner.load(model, streams=S)
    gen = Streams(S)
    kind = gen.kind
    # Preallocated and touched now, so that filling them later does not grow the RSS.
    early = np.full((PERIOD, (kind == 1).sum(), M), np.nan)  # a period DRIFT_GAP before the end
    late = np.full_like(early, np.nan)  # the last period
    c_lo = np.full(((kind == 0).sum(), M), np.inf)  # constant streams over the last WINDOW
    c_hi = np.full_like(c_lo, -np.inf)
    first_late, first_early = N - PERIOD, N - PERIOD * (DRIFT_GAP + 1)
    nan_out, lo, hi = 0, np.inf, -np.inf
    samples: list[tuple[int, float, float]] = []
    tracemalloc.start()
    start = time.perf_counter()
    for n in range(N):
        x, t = gen.next()
        y = cleaner.step(x, t)  # (S, M)
        started = ~np.isnan(y).all(axis=1)  # streams that have seen a face
        nan_out += int(np.isnan(y[started]).sum())
        lo, hi = min(lo, float(y[started].min())), max(hi, float(y[started].max()))
        if first_early <= n < first_early + PERIOD:
            early[n - first_early] = y[kind == 1]
        elif n >= first_late:
            late[n - first_late] = y[kind == 1]
        if n >= N - WINDOW:
            np.minimum(c_lo, y[kind == 0], out=c_lo)
            np.maximum(c_hi, y[kind == 0], out=c_hi)
        if n % SAMPLE == 0 or n == N - 1:
            samples.append((n, rss_mib(), tracemalloc.get_traced_memory()[0] / 2**20))
    seconds = time.perf_counter() - start
    tracemalloc.stop()

    at10 = samples[max(1, len(samples) // 10)]
    figures = {
        "cleaner": cleaner.source,
        "note": cleaner.note,
        "streams": S,
        "frames_per_stream": N,
        "frames": S * N,
        "seconds": round(seconds, 1),
        "frames_per_s": round(S * N / seconds),
        "nan_outputs": nan_out,
        "output_range": [round(lo, 4), round(hi, 4)],
        "constant_drift_last_window": float((c_hi - c_lo).max()),
        "constant_bias": float(np.abs(y[kind == 0] - gen.level[kind == 0]).max()),
        "periodic_drift": float(np.abs(late - early).max()),
        "rss_mib_at_10pct_end": [round(at10[1], 1), round(samples[-1][1], 1)],
        "traced_mib_at_10pct_end": [round(at10[2], 2), round(samples[-1][2], 2)],
        "rss_mib_min_max": [
            round(min(s[1] for s in samples), 1),
            round(max(s[1] for s in samples), 1),
        ],
    }
    print(json.dumps(figures, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps({**figures, "memory_samples": samples}, indent=1))


if __name__ == "__main__":
    main()
