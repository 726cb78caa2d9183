"""Pairs throughput on a local Dask cluster: two workers against one (issue 38's target:
>= 1.8x), each through ``faceclean pairs --cluster``, side by side in one run.

    .venv/bin/python benchmarks/cluster_pairs.py [--pairs 8] [--seconds 2] [--rounds 1]

Per round and worker count: a fresh LocalCluster (worker processes, one thread each), a
fresh output folder, ``pairs --synthetic N`` timed from the command's start to its end
(Python's start and the cluster checks included, the cluster's own start not); the
workers load the head and the tracker model on their first pair, as they would on a
real cluster. Rounds alternate one and two workers. The machine's load average is
printed: on a 2-core machine anything else running takes a worker's core.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def once(workers: int, pairs: int, seconds: float, out: Path) -> float:
    from distributed import LocalCluster

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=50) as cluster:  # fmt: skip
        argv = [sys.executable, "-m", "faceclean", "pairs", "--synthetic", str(pairs),
                "--seconds", str(seconds), "--settings", "studio", "--rates", "30",
                "--webcam-share", "0", "-o", str(out),
                "--cluster", cluster.scheduler_address]  # fmt: skip
        t0 = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True)
        return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--pairs", type=int, default=8)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    times: dict[int, list[float]] = {1: [], 2: []}
    for r in range(args.rounds):
        for w in (1, 2) if r % 2 == 0 else (2, 1):
            times[w].append(once(w, args.pairs, args.seconds, tmp / f"r{r}w{w}"))
    one, two = statistics.median(times[1]), statistics.median(times[2])
    print(f"{args.pairs} pairs of {args.seconds:g} s at 30 fps; median of {args.rounds} rounds; "
          f"load average {os.getloadavg()[0]:.2f} at the end")  # fmt: skip
    print("| workers | time (s) | pairs/min |")
    print("|---|---|---|")
    for w, s in ((1, one), (2, two)):
        print(f"| {w} | {s:.1f} | {60 * args.pairs / s:.1f} |")
    print(f"\ntwo workers: {one / two:.2f}x one worker's throughput")


if __name__ == "__main__":
    main()
