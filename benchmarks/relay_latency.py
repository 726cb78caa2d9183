"""Relay latency and throughput on loopback: the `faceclean relay` command as a process.

A sender streams a real take (noise added) as VMC bundles with ``/VMC/Ext/T`` at 60 fps
and at 1,000 fps, paced by deadlines; a receiver takes the cleaned frames. Reported:
- the relay's own added latency, receive to send (its ``--stats`` line, perf_counter_ns);
- end to end, sender to receiver (two loopback hops + the relay), matched by frame time;
- frames sent / reaching the relay / sent on / received, and the relay's drops;
- the VMC decoder against python-osc's parser on one 52-value frame.

    .venv/bin/python benchmarks/relay_latency.py [--model FILE | --method NAME]
        [--seconds 20] [--fast-seconds 10] [--json OUT]

Without --model or --method it uses the shipped default, or, while no model ships, a
stand-in LSTM checkpoint with random weights (2 layers of 128: the same step cost).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.relay import vmc
from faceclean.relay.frame import Frame
from faceclean.settings import MODELS, takes_dir

REPO = Path(__file__).resolve().parents[1]


def stand_in_model(path: Path, layers: int = 2, hidden: int = 128, seed: int = 0) -> None:
    """A faceclean-lstm/1 checkpoint with random weights (docs/ARCHITECTURE.md)."""
    rng = np.random.default_rng(seed)
    M, K, H = 52, 1, hidden
    F = M * (1 + 2 * K)
    config = {"format": "faceclean-lstm/1", "channels": list(ARKIT52), "K": K, "hidden": H,
              "layers": layers, "value_range": [0.0, 1.0], "dropout": 0.3,
              "note": "random stand-in for benchmarks"}  # fmt: skip
    arrays = {
        "config": np.array(json.dumps(config)),
        "feat_mean": np.zeros(F, np.float32),
        "feat_std": np.ones(F, np.float32),
        "out_scale": np.full(K * M, 0.01, np.float32),
        "head.w": rng.normal(0, 0.05, (K * M, H)).astype(np.float32),
        "head.b": np.zeros(K * M, np.float32),
    }
    for i in range(layers):
        arrays[f"lstm.{i}.w_ih"] = rng.normal(0, 0.05, (4 * H, F if i == 0 else H))
        arrays[f"lstm.{i}.w_hh"] = rng.normal(0, 0.05, (4 * H, H))
        arrays[f"lstm.{i}.b_ih"] = np.zeros(4 * H)
        arrays[f"lstm.{i}.b_hh"] = np.zeros(4 * H)
    np.savez(path, **{k: np.asarray(v, np.float32) if k != "config" else v
                      for k, v in arrays.items()})  # fmt: skip


def take_values(n: int) -> np.ndarray:
    """(n, 52) frames of a real take plus tracker-like noise, looped to length n."""
    folder = takes_dir()
    rng = np.random.default_rng(0)
    if folder is not None and (folder / "neurosync").is_dir():
        from faceclean import load

        values, _ = load(sorted((folder / "neurosync").glob("*.csv"))[0]).arkit()
        values = values[~np.isnan(values).all(axis=1)]
    else:
        values = rng.uniform(0, 1, (600, 52))
    values = values[np.arange(n) % len(values)]
    return np.clip(values + rng.normal(0, 0.01, values.shape), 0.0, 1.0)


def decode_speed(repeat: int = 3000) -> dict[str, float]:
    """µs per 52-value VMC frame: our decoder (a first datagram; a sender's stream) against
    python-osc's parser."""
    from pythonosc.osc_packet import OscPacket

    enc = vmc.Encoder(stamp=True)
    data = enc.encode(Frame(ARKIT52, np.full(52, 0.5), 1.0))
    # a stream: one sender's decoder, each frame with new values (its known layout)
    stream = [enc.encode(Frame(ARKIT52, np.full(52, v), v)) for v in np.linspace(0, 1, 64)]
    sender = vmc.Decoder()
    frames = iter(range(10**9))
    out = {}
    for name, fn in (
        ("ours", lambda: vmc.Decoder().feed(data)),
        ("ours, a stream", lambda: sender.feed(stream[next(frames) % 64])),
        ("python-osc", lambda: OscPacket(data)),
    ):
        fn()
        t0 = time.perf_counter()
        for _ in range(repeat):
            fn()
        out[name] = (time.perf_counter() - t0) / repeat * 1e6
    return out


def run_scenario(fps: float, seconds: float, cleaner_args: list[str]) -> dict:
    n = int(fps * seconds)
    enc = vmc.Encoder(names="arkit", stamp=True)
    values = take_values(n)
    packets = [enc.encode(Frame(ARKIT52, values[i], i / fps)) for i in range(n)]
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    rx.settimeout(0.2)
    got: list[tuple[int, bytes]] = []
    done = threading.Event()

    def receive() -> None:
        while not done.is_set():
            try:
                data = rx.recv(65536)
            except TimeoutError:
                continue
            got.append((time.perf_counter_ns(), data))

    cmd = [sys.executable, "-m", "faceclean", "relay", "--listen", "vmc://127.0.0.1:0",
           "--send", f"vmc://127.0.0.1:{rx.getsockname()[1]}", *cleaner_args]  # fmt: skip
    proc = subprocess.Popen(
        cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    ready, _, _ = select.select([proc.stdout], [], [], 60)
    if not ready:
        proc.kill()
        raise SystemExit("relay did not start")
    banner = proc.stdout.readline()
    port = int(banner.split()[1].rsplit(":", 1)[1])
    thread = threading.Thread(target=receive, daemon=True)
    thread.start()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.connect(("127.0.0.1", port))
    sent_ns = np.zeros(n, np.int64)
    start = time.perf_counter() + 0.2
    for i, p in enumerate(packets):  # paced by deadlines
        delay = start + i / fps - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        sent_ns[i] = time.perf_counter_ns()
        tx.send(p)
    done.wait(0.5)  # let the last frames land
    done.set()
    thread.join()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    stopped = next(line for line in out.splitlines() if line.startswith("stopped:"))
    words = stopped.split()
    stats = {k: int(words[words.index(k) + 1]) for k in ("in", "out", "dropped", "malformed")}
    stats["stale"] = int(words[words.index("stale") + 1].rstrip(")"))
    stats["p50_ms"] = float(words[words.index("p50") + 1])
    stats["p99_ms"] = float(words[words.index("p99") + 1])
    dec = vmc.Decoder()
    e2e = []
    for ns, data in got:
        f = dec.feed(data)
        if f is not None and f.t is not None:
            e2e.append((ns - sent_ns[round(f.t * fps)]) / 1e6)
    e2e = np.array(e2e)
    return {
        "fps": int(fps), "sent": n, "relay_in": stats["in"], "relay_out": stats["out"],
        "received": len(got), "stale": stats["stale"], "dropped": stats["dropped"],
        "relay_p50_ms": stats["p50_ms"], "relay_p99_ms": stats["p99_ms"],
        "e2e_p50_ms": float(np.percentile(e2e, 50)), "e2e_p99_ms": float(np.percentile(e2e, 99)),
        "cleaner": banner.split("(", 1)[1].rsplit(")", 1)[0],
    }  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", help="learned model file")
    p.add_argument("--method", help="a classical cleaner by name instead")
    p.add_argument("--seconds", type=float, default=20.0, help="length of the 60 fps run")
    p.add_argument("--fast-seconds", type=float, default=10.0, help="length of the 1000 fps run")
    p.add_argument("--json", help="write the results here")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if args.method:
            cleaner_args = ["--method", args.method]
        elif args.model:
            cleaner_args = ["--model", args.model]
        elif (MODELS / "default.npz").is_file():
            cleaner_args = []
        else:
            stand_in_model(Path(tmp) / "stand_in.npz")
            cleaner_args = ["--model", str(Path(tmp) / "stand_in.npz")]
        speed = decode_speed()
        rows = [run_scenario(60.0, args.seconds, cleaner_args),
                run_scenario(1000.0, args.fast_seconds, cleaner_args)]  # fmt: skip
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}; python {platform.python_version()}")  # fmt: skip
    print(f"cleaner: {rows[0]['cleaner']}")
    print(f"decode one 52-value VMC frame: ours {speed['ours']:.0f} us, "
          f"python-osc {speed['python-osc']:.0f} us")  # fmt: skip
    head = ("fps", "sent", "relay_in", "relay_out", "received", "stale", "dropped",
            "relay_p50_ms", "relay_p99_ms", "e2e_p50_ms", "e2e_p99_ms")  # fmt: skip
    print(" | ".join(head))
    for r in rows:
        print(" | ".join(f"{r[h]:.3f}" if isinstance(r[h], float) else str(r[h]) for h in head))
    if args.json:
        Path(args.json).write_text(json.dumps({"decode_us": speed, "runs": rows}, indent=1))


if __name__ == "__main__":
    main()
