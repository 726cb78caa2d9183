"""Soak the relay: a long run with a hostile sender beside a good one, memory sampled.

The `faceclean relay` command runs as a process (VMC in, VMC out). The good sender (one
socket) sends a real take at 60 fps (looped, with /VMC/Ext/T, 1 % NaN cells, 1 % late
duplicates; every few minutes the face goes silent for 2 s). Beside it, a hostile sender
(a new source port every second, so the relay meets ever-new senders) sends --garbage
datagrams a second: random bytes, truncated frames, loose Blend/Val messages with
ever-new names (long ones too) and no Apply, whole frames with ever-new names (another
sender's face), times 1e308 / NaN / -1e300, 300-name frames, over-long names, unknown
addresses. The receiver reads every relayed frame's /VMC/Ext/T, so the run counts which
good frames came through. The relay's resident memory (VmRSS) is sampled every --sample s.

    .venv/bin/python benchmarks/relay_soak.py --seconds 3600 [--sample 10] [--garbage 200]
        [--method NAME | --model FILE] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import select
import signal
import socket
import struct
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


def _time_d(t: float) -> bytes:  # /VMC/Ext/T with a float64 argument
    return osc.pad(b"/VMC/Ext/T") + osc.pad(b",d") + struct.pack(">d", t)


def garbage(rng: np.random.Generator, good: bytes, n: int) -> bytes:
    """The hostile sender's n-th datagram."""
    kind = int(rng.integers(0, 10))
    name = f"junk{n}" + "x" * int(rng.integers(0, 200))  # ever new, up to 204 bytes
    if kind == 0:
        return rng.bytes(int(rng.integers(0, 1500)))
    if kind == 1:
        return good[: int(rng.integers(0, len(good)))]
    if kind == 2:  # a loose value with a new name, never applied
        return osc.message("/VMC/Ext/Blend/Val", name, 0.5)
    if kind == 3:  # an unknown address: passthrough
        return osc.message(f"/junk/{name}", 1.0)
    if kind == 4:  # a whole face frame with new names: another sender's face
        names = [f"{name}{k}" for k in range(int(rng.integers(1, 8)))]
        return vmc.Encoder().encode(Frame(tuple(names), np.full(len(names), 0.5), None))
    if kind == 5:  # an absurd time on an otherwise good frame
        t = float(rng.choice([1e308, -1e300, float("nan"), float("inf")]))
        return osc.bundle([_time_d(t), osc.message("/VMC/Ext/Blend/Val", "jawOpen", 0.5),
                           osc.message("/VMC/Ext/Blend/Apply")])  # fmt: skip
    if kind == 6:  # too many names in one frame
        names = tuple(f"{name[:40]}{k}" for k in range(300))
        return vmc.Encoder().encode(Frame(names, np.zeros(300), None))
    if kind == 7:  # values beyond float32, as float64 arguments
        val = osc.pad(b"/VMC/Ext/Blend/Val") + osc.pad(b",sd") + osc.pad(b"jawOpen")
        return osc.bundle([val + struct.pack(">d", 1e308), osc.message("/VMC/Ext/Blend/Apply")])
    if kind == 8:  # a Live Link packet with a long, new subject
        subject = name.encode()
        return b"\x06" + struct.pack(">i", 4) + b"junk" + struct.pack(">i", len(subject)) + subject
    return b"#bundle\x00" + rng.bytes(int(rng.integers(0, 64)))


def face_times(data: bytes) -> float | None:
    """The /VMC/Ext/T of a relayed face frame (one with an Apply), else None."""
    try:
        msgs = osc.messages(data)
    except Exception:
        return None
    if not any(a == vmc.APPLY for a, _, _ in msgs):
        return None
    for a, start, end in msgs:
        if a == vmc.TIME:
            return float(osc.arguments(data, start, end)[0])
    return None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=3600.0)
    p.add_argument("--sample", type=float, default=10.0, help="memory sampling period, s")
    p.add_argument("--garbage", type=float, default=200.0, help="garbage datagrams per second")
    p.add_argument("--fps", type=float, default=60.0)
    p.add_argument("--method", default=None)
    p.add_argument("--model", default=None)
    p.add_argument("--warmup", type=float, default=300.0, help="s before RSS must be flat")
    p.add_argument("--json", help="write samples and totals here")
    args = p.parse_args()

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.2)
    received = [0]
    seen: set[float] = set()  # /VMC/Ext/T of the relayed face frames (float32 values)
    done = threading.Event()

    def receive() -> None:
        while not done.is_set():
            try:
                data = rx.recv(65536)
                received[0] += 1
                t = face_times(data)
                if t is not None:
                    seen.add(t)
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
    hostile = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    hostile.connect(("127.0.0.1", port))
    good_times: list[float] = []  # float32 sender times of the good frames sent
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
            good_times.append(float(np.float32(t_face)))
            if rng.random() < 0.01:  # a late duplicate
                tx.send(enc.encode(Frame(ARKIT52, x, t_face - 0.05)))
        if i % int(args.fps) == 0:  # a new source port: ever-new senders
            hostile.close()
            hostile = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            hostile.connect(("127.0.0.1", port))
        for _ in range(rng.poisson(args.garbage / args.fps)):
            hostile.send(garbage(rng, good, junk))
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
    warm = [s for s in samples if s[0] >= min(args.warmup, args.seconds / 4)]
    growth = (warm[-1][1] - warm[0][1]) / 1024 if len(warm) > 1 else float("nan")
    spread = (max(s[1] for s in warm) - min(s[1] for s in warm)) / 1024 if warm else float("nan")
    relayed = sum(1 for t in good_times if t in seen)
    print(f"good frames sent {sent}, relayed {relayed} ({sent - relayed} not), garbage {junk}, "
          f"datagrams received {received[0]}, rc {proc.returncode}")  # fmt: skip
    print(f"RSS after warm-up ({warm[0][0]:.0f} s on): growth {growth:+.2f} MiB, "
          f"max - min {spread:.2f} MiB over {warm[-1][0] - warm[0][0]:.0f} s")  # fmt: skip
    print(stopped.strip())
    if args.json:
        Path(args.json).write_text(json.dumps({
            "samples": samples, "sent": sent, "relayed": relayed, "garbage": junk,
            "received": received[0], "rss_growth_mib": growth, "rss_spread_mib": spread,
            "stopped": stopped.strip(), "banner": banner,
        }, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
