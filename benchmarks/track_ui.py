"""`faceclean track --camera --ui`: does the page (the camera image among it) slow the loop?

    .venv/bin/python benchmarks/track_ui.py [--seconds 20] [--runs 2] [--pin]

A rendered 640x480 video (``track_video.render``) stands in for the camera (played at its
own pace, 30 fps). Runs alternate: ``track --camera VIDEO --send vmc://...`` alone, then
with ``--ui`` and a headless Chromium (Debian's, through playwright, as the tests drive
it) keeping the page open for the whole run, the camera's image streaming. Each run's
final ``stopped:`` line gives the camera's frames and drops, MediaPipe's p50, and what
the loop adds to it (cleaning, the head filter, encoding, sending, and with ``--ui`` the
page's ring and the image handed over) at p50 and p99, in wall time. ``--pin`` gives the
command CPU 0 and the browser CPU 1 (a desktop whose browser does not share the loop's
core). Prints one JSON object: every run, the medians per kind, the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import socket
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE.parent / "tests" / "ui"))
from track_video import render  # noqa: E402

STOPPED = re.compile(
    r"stopped: camera (\d+) dropped (\d+) .*MediaPipe p50 ([\d.]+) ms, "
    r"clean\+send p50 ([\d.]+) p99 ([\d.]+) ms"
)
URL = re.compile(r"tuning page: (http://\S+)")


def run(video: Path, url: str, ui: bool, pin: bool, browser) -> dict:
    cmd = [sys.executable, "-m", "faceclean", "track", "--camera", str(video), "--send", url]
    cmd = (["taskset", "-c", "0"] if pin else []) + cmd
    if ui:
        cmd += ["--ui", "--no-browser"]
    env = dict(os.environ, PYTHONPATH=str(HERE.parent / "src"))
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)  # fmt: skip
    images = None
    if ui:
        from test_ui_page import Tab

        for line in proc.stdout:
            found = URL.search(line)
            if found:
                break
        tab = Tab(browser, found[1])
        tab.until("window.faceclean.images > 0")
        out_rest = []
        for line in proc.stdout:  # the run goes on until the stand-in camera ends
            out_rest.append(line)
        images = tab.js("window.faceclean.images")
        tab.page.close()
        said = "".join(out_rest)
    else:
        said = proc.stdout.read()
    proc.wait()
    found = STOPPED.search(said)
    if found is None:
        raise SystemExit(f"no stopped line: {said[-500:]} {proc.stderr.read()[-2000:]}")
    captured, dropped, mp, p50, p99 = found.groups()
    return {"ui": ui, "captured": int(captured), "dropped": int(dropped),
            "mediapipe_p50_ms": float(mp), "added_p50_ms": float(p50),
            "added_p99_ms": float(p99), "images_drawn": images}  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--runs", type=int, default=2, help="runs of each kind")
    p.add_argument("--pin", action="store_true")
    a = p.parse_args()
    from headless import BROWSER_ARGS, CHROMIUM
    from playwright.sync_api import sync_playwright

    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(0.5)
    stop = threading.Event()

    def drain() -> None:
        while not stop.is_set():
            try:
                sink.recv(65535)
            except (TimeoutError, OSError):
                continue

    reader = threading.Thread(target=drain)
    reader.start()
    runs = []
    try:
        with tempfile.TemporaryDirectory() as tmp, sync_playwright() as pw:
            video = Path(tmp) / "camera.mp4"
            render(video, a.seconds)
            if a.pin:
                os.sched_setaffinity(0, {1})  # the browser, started from here, inherits it
            browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=BROWSER_ARGS)
            url = f"vmc://127.0.0.1:{sink.getsockname()[1]}"
            for _ in range(a.runs):
                for ui in (False, True):
                    runs.append(run(video, url, ui, a.pin, browser))
            browser.close()
    finally:
        stop.set()
        reader.join()
        sink.close()

    def median(ui: bool, key: str) -> float:
        return float(np.median([r[key] for r in runs if r["ui"] == ui]))

    keys = ("mediapipe_p50_ms", "added_p50_ms", "added_p99_ms")
    summary = {
        ("page" if ui else "alone"): {k: median(ui, k) for k in keys} for ui in (False, True)
    }
    for kind, ui in (("alone", False), ("page", True)):
        summary[kind]["dropped_share"] = float(np.median(
            [r["dropped"] / max(r["captured"], 1) for r in runs if r["ui"] == ui]))  # fmt: skip
    print(json.dumps({"runs": runs, "median": summary, "pin": a.pin,
                      "load_average": os.getloadavg()}, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
