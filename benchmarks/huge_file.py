"""A ~200 MB Live Link Face CSV through ``faceclean clean``: streamed in constant memory.

    .venv/bin/python benchmarks/huge_file.py            # 25, 100 and 200 MB files
    .venv/bin/python benchmarks/huge_file.py --mb 50    # one size

Each file is a real take's rows repeated with continuous timecodes (tracking-loss rows
included), written to a temporary folder. Each clean runs in a fresh process that reports
its own peak RSS (``ru_maxrss``): the streaming path (a causal cleaner, Live Link to Live
Link) must stay flat as the file grows; the whole-file path (the same file to JSON) is
shown for contrast on the smallest size.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from faceclean.settings import takes_dir

RUN = """
import resource, sys
from faceclean.cli import main
rc = main(sys.argv[1:])
print("PEAK", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, rc)
"""


def make_file(path: Path, mb: float) -> int:
    """Write a Live Link CSV of about ``mb`` MB; returns its number of rows."""
    from faceclean.io.livelink_csv import timecode_seconds, timecode_text

    take = takes_dir() / "alexdjulin" / "apfel.csv"
    lines = take.read_bytes().splitlines(keepends=True)
    head, rows = lines[0], [r.split(b",", 1) for r in lines[1:]]
    start = timecode_seconds(rows[0][0])
    span = timecode_seconds(rows[-1][0]) - start + 1 / 60  # s, one copy of the take
    n, size, copy = 0, len(head), 0
    with open(path, "wb") as f:
        f.write(head)
        while size < mb * 1e6:
            for tc, rest in rows:
                t = timecode_seconds(tc) + copy * span
                line = timecode_text(t).encode() + b"," + rest
                f.write(line)
                size += len(line)
                n += 1
            copy += 1
    return n


def clean(src: Path, out: Path, method: str) -> tuple[float, float]:
    """(peak RSS MiB, seconds) of ``faceclean clean src -o out --method method``."""
    t0 = time.perf_counter()
    argv = [sys.executable, "-c", RUN, "clean", str(src), "-o", str(out), "--method", method]
    done = subprocess.run(argv, capture_output=True, text=True, check=True)
    seconds = time.perf_counter() - t0
    peak = [line for line in done.stdout.splitlines() if line.startswith("PEAK")][0].split()
    assert peak[2] == "0", done.stderr
    return int(peak[1]) / 1024, seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=float, action="append", help="file size(s) in MB")
    ap.add_argument("--method", default="one-euro")
    args = ap.parse_args()
    sizes = args.mb or [25.0, 100.0, 200.0]
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        print(f"{'file':>10} {'rows':>9} {'path':>9} {'peak RSS':>10} {'time':>8}")
        for mb in sizes:
            src = folder / f"take_{mb:g}.csv"
            rows = make_file(src, mb)
            real = src.stat().st_size / 1e6
            peak, s = clean(src, folder / "out.csv", args.method)
            print(f"{real:8.1f}MB {rows:9d} {'stream':>9} {peak:7.1f}MiB {s:7.1f}s", flush=True)
            if mb == min(sizes):
                peak, s = clean(src, folder / "out.json", args.method)
                print(f"{real:8.1f}MB {rows:9d} {'whole':>9} {peak:7.1f}MiB {s:7.1f}s", flush=True)
            src.unlink()


if __name__ == "__main__":
    main()
