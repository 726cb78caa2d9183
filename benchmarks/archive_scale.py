"""An hour of 60 fps through ``faceclean clean``, NPZ to NPZ, against a bare load and save.

    .venv/bin/python benchmarks/archive_scale.py              # 60 minutes, 3 rounds
    .venv/bin/python benchmarks/archive_scale.py --minutes 10 --rounds 1
    .venv/bin/python benchmarks/archive_scale.py --format csv --rounds 1   # plain CSV

One synthetic take (52 ARKit channels, jittered 60 fps, a tracking-loss gap, the channels
raw MediaPipe keeps near 0 kept there, so that ``--tracker mediapipe`` pays its whole
signature check, trackers/signature.py) is written once; then, side by side in the same
run and interleaved round by round, fresh processes:

- ``bare``: ``io.load`` then ``io.save`` of the same arrays, uncompressed (the floor);
- ``faceclean clean IN -o OUT`` for each cleaner, compiled (numba, the whole-take path)
  and with FACECLEAN_NUMBA=0 (the numpy path, as without numba), once each;
- a 1-frame file, compiled default and numba off (numba is never loaded for it).

Each process's time is the median over rounds; its peak RSS (VmHWM). Every process reads
its modules' bytecode from a cache in the run's folder (PYTHONPYCACHEPREFIX), as an
installed package does: a shell with PYTHONDONTWRITEBYTECODE=1 (this sandbox's) would
compile faceclean's sources in every process, ~0.1 s more for a clean's ~50 modules than
for the floor's ~15. Each run is done once before the rounds (bytecode and numba's
caches written). Memory of
the take's own copies: the same clean in one process under ``tracemalloc`` with numba
imported first (numba's import is a fixed ~45 MB of Python objects and ~160 MB of RSS,
whatever the take), over the take's own arrays (times + values). The written file is
checked lossless: bit for bit the in-process clean.

``--format csv``: the same take as a plain CSV (repr-exact numbers, 221 MB for the hour),
CSV to CSV: a causal cleaner streams the file in blocks (io/stream.py, runs of frames
compiled), the LSTM reads it whole (plain_csv.read, a block of lines at a time); ``bare``
is ``io.load`` + ``io.save`` of the CSV. No tracemalloc column (its hooks on the parser's
many small objects would time something else); peak RSS says the memory.
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

import numpy as np

CLEANERS = {
    "default": [],
    "--tracker mediapipe": ["--tracker", "mediapipe"],
    "one-euro": ["--method", "one-euro"],
    "ema": ["--method", "ema"],
    "kalman": ["--method", "kalman"],
    "lstm": ["--method", "lstm"],
}
# Peak RSS: VmHWM, this process's own (ru_maxrss would carry over the parent's from fork).
RUN = """
import sys, time
t0 = time.perf_counter()
from faceclean.cli import main
if sys.argv[1] == "bare":
    from faceclean import io
    io.save(io.load(sys.argv[2]), sys.argv[3])
else:
    assert main(["clean", *sys.argv[2:]]) == 0
s = time.perf_counter() - t0
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
print("RESULT", s, hwm)
"""
TRACE = """
import sys, tracemalloc
import numba  # noqa: F401 - its fixed cost kept out of the take's
from faceclean import io
from faceclean.cli import main
a = io.load(sys.argv[1]); own = a.times.nbytes + a.values.nbytes; del a
tracemalloc.start()
assert main(["clean", *sys.argv[1:]]) == 0
print("RESULT", tracemalloc.get_traced_memory()[1] / own)
"""


def make_take(path: Path, minutes: float) -> int:
    from faceclean import Animation, save
    from faceclean.channels import ARKIT52
    from faceclean.trackers.signature import SILENT

    n = int(minutes * 3600) + 1
    rng = np.random.default_rng(0)
    t = np.arange(n) / 60.0 + rng.uniform(-0.002, 0.002, n)
    t[0] = 0.0
    phase, f = rng.uniform(0, 2 * np.pi, 52), rng.uniform(0.2, 1.0, 52)  # Hz
    x = 0.4 + 0.3 * np.sin(2 * np.pi * f * t[:, None] + phase) + rng.normal(0, 0.02, (n, 52))
    x = np.clip(x, 0.0, 1.0)
    for name in SILENT:  # as raw MediaPipe: so --tracker mediapipe's check reads it whole
        x[:, ARKIT52.index(name)] = rng.uniform(0.0, 0.006, n)
    x[1000:1010] = np.nan  # a tracking loss
    save(Animation(t, x, ARKIT52), path)
    return n


PYC: dict[str, str] = {}  # the bytecode cache's environment, set by main


def child(code: str, args: list[str], env: dict | None = None) -> list[float]:
    base = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                         env={**base, **PYC, **(env or {})}, check=True).stdout  # fmt: skip
    return [float(v) for v in out.split("RESULT")[-1].split()]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--format", choices=("npz", "csv"), default="npz")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    PYC["PYTHONPYCACHEPREFIX"] = str(tmp / "pycache")
    load_before = os.getloadavg()[0]
    ext = args.format
    src, out = tmp / f"take.{ext}", tmp / f"out.{ext}"
    frames = make_take(src, args.minutes)
    one = tmp / f"one.{ext}"
    make_take(one, 1 / 3600)
    runs = {"bare": (["bare", str(src), str(out)], None)}
    for name, flags in CLEANERS.items():
        runs[name] = (["clean", str(src), "-o", str(out), *flags], None)
    runs["1-frame default"] = (["clean", str(one), "-o", str(tmp / f"o1.{ext}")], None)
    runs["1-frame default, numba off"] = (runs["1-frame default"][0], {"FACECLEAN_NUMBA": "0"})
    for argv, env in runs.values():  # bytecode and numba's caches written, the file cached
        child(RUN, argv, env)
    times: dict[str, list[float]] = {k: [] for k in runs}
    rss: dict[str, float] = {}
    for _ in range(args.rounds):
        for name, (argv, env) in runs.items():
            s, kb = child(RUN, argv, env)
            times[name].append(s)
            rss[name] = max(rss.get(name, 0.0), kb / 1024)
    numpy_s, traced = {}, {}
    for name, flags in CLEANERS.items():  # the numpy path, once
        numpy_s[name] = child(RUN, ["clean", str(src), "-o", str(out), *flags],
                              {"FACECLEAN_NUMBA": "0"})[0]  # fmt: skip
    if ext == "npz":
        traced = {name: child(TRACE, [str(src), "-o", str(out), *flags])[0]
                  for name, flags in CLEANERS.items()}  # fmt: skip
    lossless = check_lossless(src, out)
    bare = statistics.median(times["bare"])
    print(
        f"{frames} frames ({args.minutes:g} min at 60 fps), {src.stat().st_size / 1e6:.1f} MB "
        f"{ext}; median of {args.rounds} rounds; load average {load_before:.2f} before, "
        f"{os.getloadavg()[0]:.2f} after\n"
    )
    print(
        "| run | time (s) | x bare | numpy path (s) | compiled speed-up | peak RSS (MB) "
        "| take-dependent peak (x arrays) |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in runs:
        s = statistics.median(times[name])
        np_s = numpy_s.get(name)
        cells = [name, f"{s:.2f}", f"{s / bare:.1f}x" if "1-frame" not in name else "",
                 f"{np_s:.2f}" if np_s else "", f"{np_s / s:.1f}x" if np_s else "",
                 f"{rss[name]:.0f}", f"{traced[name]:.2f}x" if name in traced else ""]  # fmt: skip
        print("| " + " | ".join(cells) + " |")
    print(f"\nwritten file lossless (bit for bit the in-process clean): {lossless}")


def check_lossless(src: Path, out: Path) -> bool:
    """Each compiled cleaner's written file (the LSTM's aside: 8 s) is its clean in this
    process, bit for bit."""
    from faceclean import io
    from faceclean.cli import options
    from faceclean.cli.clean import add_arguments

    take = io.load(src)
    for name, flags in CLEANERS.items():
        if name == "lstm":
            continue
        child(RUN, ["clean", str(src), "-o", str(out), *flags])
        ap = argparse.ArgumentParser()
        add_arguments(ap)
        cleaner = options.choice(ap.parse_args([str(src), *flags])).build(take.names)
        want = cleaner.clean(take).values
        if not np.array_equal(io.load(out).values, want, equal_nan=True):
            return False
    return True


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"(benchmark ran {time.perf_counter() - t0:.0f} s)")
