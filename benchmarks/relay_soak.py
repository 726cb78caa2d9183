"""Soak the relay: a long run under good and garbage traffic, memory sampled over time.

The `faceclean relay` command runs as a process (VMC in, VMC out). One thread sends a real
take at 60 fps (looped, with /VMC/Ext/T) and, between frames, garbage: random bytes,
truncated frames, loose Blend/Val messages with random names and no Apply, unknown
addresses, late and duplicate frames, NaN values; every few minutes the face goes silent
for 2 s. The relay's resident memory (VmRSS) is sampled every --sample seconds.

    .venv/bin/python benchmarks/relay_soak.py --seconds 3600 [--sample 10] [--garbage 200]
        [--method NAME | --model FILE] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.relay import osc, vmc
from faceclean.relay.frame import Frame

sys.path.insert(0, str(Path(__file__).resolve().parent))
from relay_latency import take_values  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SILENCE_EVERY = 300.0  # s
SILENCE = 2.0  # s


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return -1


def garbage(rng: np.random.Generator, good: bytes) -> bytes:
    kind = int(rng.integers(0, 5))
    if kind == 0:
        return rng.bytes(int(rng.integers(0, 1500)))
    if kind == 1:
        return good[: int(rng.integers(0, len(good)))]
    if kind == 2:  # a loose value with a random name, never applied
        return osc.message("/VMC/Ext/Blend/Val", f"junk{int(rng.integers(1 << 30))}", 0.5)
    if kind == 3:  # an unknown address: passthrough
        return osc.message(f"/junk/{int(rng.integers(1 << 30))}", 1.0)
    return b"#bundle\x00" + rng.bytes(int(rng.integers(0, 64)))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=3600.0)
    p.add_argument("--sample", type=float, default=10.0, help="memory sampling period, s")
    p.add_argument("--garbage", type=float, default=200.0, help="garbage datagrams per second")
    p.add_argument("--fps", type=float, default=60.0)
    p.add_argument("--method", default=None)
    p.add_argument("--model", default=None)
    p.add_argument("--json", help="write samples and totals here")
    args = p.parse_args()

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.2)
    received = [0]
    done = threading.Event()

    def receive() -> None:
        while not done.is_set():
            try:
                rx.recv(65536)
                received[0] += 1
            except TimeoutError:
                pass

    cleaner = ["--method", args.method] if args.method else []
    cleaner += ["--model", args.model] if args.model else []
    cmd = [sys.executable, "-m", "faceclean", "relay", "--listen", "vmc://127.0.0.1:0",
           "--send", f"vmc://127.0.0.1:{rx.getsockname()[1]}", "--stats", str(args.sample),
           *cleaner]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, text=True)
    ready, _, _ = select.select([proc.stdout], [], [], 60)
    if not ready:
        proc.kill()
        raise SystemExit("relay did not start")
    banner = proc.stdout.readline().strip()
    port = int(banner.split()[1].rsplit(":", 1)[1])
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")))
    reader.start()
    threading.Thread(target=receive, daemon=True).start()

    rng = np.random.default_rng(0)
    enc = vmc.Encoder(names="arkit", stamp=True)
    values = take_values(3600)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.connect(("127.0.0.1", port))
    samples: list[tuple[float, int, int]] = []
    start = time.monotonic()
    next_sample = start
    sent = junk = 0
    i = 0
    t_face = 0.0  # s, sender time
    while (now := time.monotonic()) - start < args.seconds:
        if now >= next_sample:
            samples.append((now - start, rss_kib(proc.pid), sent))
            next_sample += args.sample
        elapsed = now - start
        silent = elapsed % SILENCE_EVERY > SILENCE_EVERY - SILENCE
        x = values[i % len(values)].copy()
        if rng.random() < 0.01:
            x[int(rng.integers(52))] = np.nan
        t_face = elapsed
        good = enc.encode(Frame(ARKIT52, x, t_face))
        if not silent:
            tx.send(good)
            sent += 1
            if rng.random() < 0.01:  # a late duplicate
                tx.send(enc.encode(Frame(ARKIT52, x, t_face - 0.05)))
        for _ in range(rng.poisson(args.garbage / args.fps)):
            tx.send(garbage(rng, good))
            junk += 1
        i += 1
        time.sleep(max(0.0, start + i / args.fps - time.monotonic()))
    samples.append((time.monotonic() - start, rss_kib(proc.pid), sent))
    done.wait(0.3)
    done.set()
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    reader.join(timeout=10)
    stopped = next((ln for ln in lines if ln.startswith("stopped:")), "")

    print(banner)
    print(f"{'t (s)':>8} {'RSS (MiB)':>10} {'frames sent':>12}")
    for t, kib, n in samples:
        print(f"{t:8.0f} {kib / 1024:10.2f} {n:12d}")
    warm = [s for s in samples if s[0] >= min(60.0, args.seconds / 4)]
    growth = (warm[-1][1] - warm[0][1]) / 1024 if len(warm) > 1 else float("nan")
    print(f"good frames sent {sent}, garbage {junk}, received {received[0]}, rc {proc.returncode}")
    print(f"RSS growth after warm-up: {growth:+.2f} MiB over {warm[-1][0] - warm[0][0]:.0f} s")
    print(stopped.strip())
    if args.json:
        Path(args.json).write_text(json.dumps({
            "samples": samples, "sent": sent, "garbage": junk, "received": received[0],
            "rss_growth_mib": growth, "stopped": stopped.strip(), "banner": banner,
        }, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
