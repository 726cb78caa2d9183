"""Relay latency with the tuning page open, against the relay alone, side by side.

Each run: ``faceclean relay`` (the shipped default cleaner; VMC in, Live Link out to a
UDP sink) fed by ``faceclean replay --loop`` of a shared take at its own rate (60 fps)
for ``--seconds``; in the "page" runs the relay has ``--ui`` and a headless Chromium
(Debian's, through playwright, as the tests drive it) keeps the page open and streaming.
Runs alternate (relay, page, relay, page, ...) so that the machine's load weighs on both
alike. Reported: the relay's own latency, receive to send, p50 and p99 (its final
``stopped:`` line), the median over the runs of each kind and their ratio; the messages a
second the page got and the frames they carried; the time from the page's live channel
opening to its first frames.

``--viewer socket`` keeps the page's live channel open with a plain WebSocket client
(websockets) instead of Chromium: what the page's server costs the relay process, without
a browser's rendering on the same CPUs.

Then, once per sitting, how soon the page shows a stream already flowing: ``relay --ui``
fed by the replay for 2 s, then a fresh tab opens the page; the times from the tab's
navigation start to the first frames message and to the first drawn faces (the page's own
clock, ``performance.now()``), median of ``--runs``.

``--pin`` gives the relay CPU 0 and everything else (the replay, Chromium, this script)
CPU 1, in both kinds of run: a desktop where the browser does not share the relay's
core (on a 2-core machine without it, software-rendered WebGL competes with the relay
for the CPU, which measures the machine rather than the page's server).

    .venv/bin/python benchmarks/ui_latency.py [--seconds 20] [--runs 3] [--pin] [--json OUT]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
STOPPED = re.compile(r"stopped: .*latency p50 ([\d.]+) ms p99 ([\d.]+) ms")
OUT = re.compile(r"stopped: in (\d+) out (\d+)")


def sink() -> tuple[socket.socket, threading.Event]:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(0.2)
    stop = threading.Event()

    def drain() -> None:
        while not stop.is_set():
            with contextlib.suppress(TimeoutError, OSError):  # OSError: closed at the end
                s.recv(65535)

    threading.Thread(target=drain, daemon=True).start()
    return s, stop


class SocketViewer:
    """The page's live channel held open by a websockets client that reads every message."""

    def __init__(self, url: str) -> None:
        from websockets.sync.client import connect

        host, token = url.split("//")[1].split("/")[0], url.split("token=")[1]
        self.ws = connect(f"ws://{host}/live?token={token}", max_size=None)
        self.frames = self.messages = 0
        self.first: float | None = None
        self.opened = time.monotonic()
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        with contextlib.suppress(Exception):
            for raw in self.ws:
                m = json.loads(raw)
                if m.get("type") == "frames":
                    self.messages += 1
                    self.frames += len(m["t"])
                    if self.first is None and m["t"]:
                        self.first = time.monotonic()

    def close(self) -> dict:
        self.ws.close()
        self.thread.join(5)
        first = None if self.first is None else (self.first - self.opened) * 1e3
        return {"page_frames": self.frames, "page_messages": self.messages,
                "first_frames_ms": first}  # fmt: skip


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def one_run(take: Path, seconds: float, browser, env: dict, pin: bool, nice: int = 10) -> dict:
    out, stop = sink()
    port = free_port()
    page = browser is not None
    args = [sys.executable, "-m", "faceclean", "relay", "--listen", f"vmc://127.0.0.1:{port}",
            "--send", f"livelink://127.0.0.1:{out.getsockname()[1]}"]  # fmt: skip
    args += ["--ui", "--no-browser", "--ui-nice", str(nice)] if page else []
    relay = subprocess.Popen(
        args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )
    if pin:  # the relay (every thread it starts after this) alone on CPU 0
        os.sched_setaffinity(relay.pid, {0})
    line = relay.stdout.readline()
    tab, result = None, {"page": page}
    viewer = None
    if page:
        url = line.split("tuning page: ")[1].strip()
        relay.stdout.readline()
        if browser == "socket":
            viewer = SocketViewer(url)
        else:
            tab = browser.new_page(viewport={"width": 1400, "height": 1000})
            tab.goto(url)
    replay = subprocess.Popen(
        [sys.executable, "-m", "faceclean", "replay", str(take), "--loop",
         "--send", f"vmc://127.0.0.1:{port}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
    )  # fmt: skip
    time.sleep(seconds)
    if tab is not None:
        api = tab.evaluate(
            "({frames: faceclean.frames, pushes: faceclean.pushes, open: faceclean.openMs,"
            " first: faceclean.firstFrameMs})"
        )
        result["page_frames"], result["page_messages"] = api["frames"], api["pushes"]
        result["first_frames_ms"] = api["first"] - api["open"]
        tab.close()
    if viewer is not None:
        result.update(viewer.close())
    replay.kill()
    replay.wait()
    relay.send_signal(signal.SIGINT)
    text = relay.communicate(timeout=60)[0]
    stop.set()
    out.close()
    m, n = STOPPED.search(text), OUT.search(text)
    result.update(p50=float(m[1]), p99=float(m[2]), frames_in=int(n[1]), frames_out=int(n[2]))
    result["seconds"] = seconds
    return result


def first_sight(take: Path, browser, env: dict, runs: int) -> dict:
    """ms from a fresh tab's navigation start to the first frames and the first faces,
    on a stream that is already flowing (median over ``runs``)."""
    frames, faces = [], []
    for _ in range(runs):
        out, stop = sink()
        port = free_port()
        relay = subprocess.Popen(
            [sys.executable, "-m", "faceclean", "relay", "--listen", f"vmc://127.0.0.1:{port}",
             "--send", f"livelink://127.0.0.1:{out.getsockname()[1]}", "--ui", "--no-browser"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        )  # fmt: skip
        url = relay.stdout.readline().split("tuning page: ")[1].strip()
        replay = subprocess.Popen(
            [sys.executable, "-m", "faceclean", "replay", str(take), "--loop",
             "--send", f"vmc://127.0.0.1:{port}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
        )  # fmt: skip
        time.sleep(2.0)  # the stream flows before the page opens
        tab = browser.new_page(viewport={"width": 1400, "height": 1000})
        tab.goto(url)
        # polled from here: wait_for_function evaluates a string in the page, which the
        # page's Content-Security-Policy (no 'unsafe-eval') refuses
        deadline = time.monotonic() + 30.0
        while not tab.evaluate("!!(window.faceclean && window.faceclean.firstFaceMs !== null)"):
            if time.monotonic() > deadline:
                raise SystemExit("the page drew no face within 30 s")
            time.sleep(0.02)
        got = tab.evaluate("[faceclean.firstFrameMs, faceclean.firstFaceMs]")
        frames.append(got[0])
        faces.append(got[1])
        tab.close()
        replay.kill()
        replay.wait()
        relay.send_signal(signal.SIGINT)
        relay.communicate(timeout=60)
        stop.set()
        out.close()
    return {"first_frames_ms": float(np.median(frames)), "first_faces_ms": float(np.median(faces)),
            "first_runs": runs}  # fmt: skip


def browser_nice(nice: int) -> str:
    """Every Chromium process yields at ``nice`` (its sessions where sessions weigh, else
    its threads), as the relay's own --ui-nice does for the page's browser
    (faceclean/ui/priority.py); this script and the relay are never lowered. What was set."""
    from faceclean.ui import priority

    found = subprocess.run(["pgrep", "-f", "chromium"], capture_output=True, text=True)
    return priority.yield_cpu({int(p) for p in found.stdout.split()}, nice)


def main() -> None:
    from headless import BROWSER_ARGS, CHROMIUM
    from playwright.sync_api import sync_playwright

    from faceclean.settings import takes_dir

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--pin", action="store_true", help="the relay on CPU 0, the rest on CPU 1")
    p.add_argument("--viewer", choices=("chromium", "socket"), default="chromium")
    p.add_argument(
        "--browser-nice",
        type=int,
        default=0,
        help="the nice of the browser (0-19: lower priority; see ui/priority.py)",
    )
    p.add_argument(
        "--ui-nice",
        type=int,
        default=10,
        help="relay --ui-nice: the nice the relay gives a CPU-drawn page's browser",
    )
    p.add_argument("--json")
    a = p.parse_args()
    if a.pin:
        os.sched_setaffinity(0, {1})  # inherited by Chromium and the replay
    take = sorted((takes_dir() / "neurosync").glob("*.csv"))[0]
    env = dict(os.environ, PYTHONPATH=str(REPO / "src"))
    runs = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=BROWSER_ARGS)
        if a.browser_nice:
            browser_nice(a.browser_nice)
        for i in range(2 * a.runs):
            viewer = browser if a.viewer == "chromium" else "socket"
            r = one_run(take, a.seconds, viewer if i % 2 else None, env, a.pin, a.ui_nice)
            runs.append(r)
            print(json.dumps(r), flush=True)
        sight = first_sight(take, browser, env, a.runs) if a.viewer == "chromium" else {}
        browser.close()
    summary = {"take": take.name, "runs": runs, "cpus": os.cpu_count(), "pin": a.pin,
               "viewer": a.viewer,
               "load": os.getloadavg()}  # fmt: skip
    for kind, page in (("relay", False), ("page", True)):
        rs = [r for r in runs if r["page"] == page]
        summary[kind] = {k: float(np.median([r[k] for r in rs])) for k in ("p50", "p99")}
    summary["p99_ratio"] = summary["page"]["p99"] / summary["relay"]["p99"]
    summary["p50_ratio"] = summary["page"]["p50"] / summary["relay"]["p50"]
    paged = [r for r in runs if r["page"]]
    summary["messages_per_s"] = float(np.median([r["page_messages"] / r["seconds"] for r in paged]))
    summary["first_frames_ms"] = float(np.median([r["first_frames_ms"] for r in paged]))
    summary.update({f"page_opened_{k}": v for k, v in sight.items()})
    print(json.dumps({k: v for k, v in summary.items() if k != "runs"}, indent=1))
    if a.json:
        Path(a.json).write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
