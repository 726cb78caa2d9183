"""`faceclean track --camera` on one core: what cleaning and sending add to MediaPipe, p99.

    .venv/bin/python benchmarks/track_live.py [--seconds 10] [--core 1] [--method NAME]

Issue 36's target: live, the cleaner and sending add at most 2 ms to MediaPipe's time per
frame at p99. A rendered 640x480 video (``track_video.render``) stands in for the camera
(played at its own pace, 30 fps), ``faceclean track --camera VIDEO --send vmc://...`` runs
in a child pinned to ``--core`` (``taskset``), sending to a UDP socket here; its final
``stopped:`` line gives MediaPipe's p50 and what the loop adds (the cleaner, the head
filter, encoding, sending) at p50 and p99, in wall time: on a shared core that counts
the other jobs' turns too. ``--cpu`` runs the same loop here instead, timed by the loop
thread's CPU clock (``time.thread_time_ns``): what the loop itself spends per frame,
whatever the load (MediaPipe's own column is then meaningless: its work runs on its
threads). Prints one JSON object with the load average.
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

sys.path.insert(0, str(Path(__file__).parent))
from track_video import render  # noqa: E402


def in_process(video: Path, url: str, method: str | None) -> str:
    """The live loop of ``track --camera`` here, timed by the loop thread's CPU clock."""
    import time

    from faceclean.channels import POSE
    from faceclean.cli import options, parser
    from faceclean.cli.relay import build_cleaner
    from faceclean.relay import parse
    from faceclean.relay.loop import warm_up
    from faceclean.trackers.face import FaceTracker
    from faceclean.trackers.live import Live
    from faceclean.trackers.video import Camera

    argv = ["track", "--camera", str(video), "--send", url]
    args = parser().parse_args(argv + (["--method", method] if method else []))
    choice = options.choice(args)
    cleaner, _ = build_cleaner(choice)
    warm_up(cleaner)
    with (FaceTracker() as tracker, Camera(str(video)) as camera,
          Live(camera, tracker, cleaner, parse(url, "send"), pose=choice.build_pose(POSE),
               clock=time.thread_time_ns) as live):  # fmt: skip
        camera.start()
        return "stopped: " + live.run().line()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--core", type=int, default=1)
    p.add_argument("--method", default=None, help="a cleaner other than the default")
    p.add_argument("--cpu", action="store_true", help="in process, the loop thread's CPU time")
    a = p.parse_args()
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(1.0)
    got = [0]

    def drain() -> None:
        while True:
            try:
                sink.recv(65535)
                got[0] += 1
            except TimeoutError:
                if stop.is_set():
                    return
            except OSError:
                return

    stop = threading.Event()
    reader = threading.Thread(target=drain)
    reader.start()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            video = Path(tmp) / "camera.mp4"
            render(video, a.seconds)
            url = f"vmc://127.0.0.1:{sink.getsockname()[1]}"
            if a.cpu:
                os.sched_setaffinity(0, {a.core})
                said = in_process(video, url, a.method)
            cmd = ["taskset", "-c", str(a.core), sys.executable, "-m", "faceclean", "track",
                   "--camera", str(video), "--send", url]  # fmt: skip
            if a.method:
                cmd += ["--method", a.method]
            if not a.cpu:
                done = subprocess.run(cmd, capture_output=True, text=True)
                said = done.stdout if done.returncode == 0 else ""
                if not said:
                    raise SystemExit(done.stderr[-2000:])
    finally:
        stop.set()
        reader.join()
        sink.close()
    line = [ln for ln in said.splitlines() if ln.startswith("stopped:")]
    nums = re.search(r"MediaPipe p50 ([\d.]+) ms, clean\+send p50 ([\d.]+) p99 ([\d.]+) ms",
                     line[0])  # fmt: skip
    res = {"clock": "loop thread CPU" if a.cpu else "wall", "stopped": line[0],
           "received": got[0], "load_average": os.getloadavg()}  # fmt: skip
    if nums:
        res |= dict(zip(("mediapipe_p50_ms", "added_p50_ms", "added_p99_ms"),
                        map(float, nums.groups()), strict=True))  # fmt: skip
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
