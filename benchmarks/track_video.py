"""`faceclean track` on a 60 s, 30 fps, 640x480 video on one core, MediaPipe's cost beside it.

    .venv/bin/python benchmarks/track_video.py [--seconds 60] [--core 0]

Issue 36's target: such a video tracked and cleaned in under 60 s on one core, MediaPipe's
own cost (the floor) reported beside the total.

1. A video: 10 s (300 frames) of a rendered face (studio scene, 480 px) turning, talking
   and blinking, centred on a 640x480 picture, played forth and back to ``--seconds`` and
   written as an mp4 (mp4v, OpenCV's writer) in a temporary folder.
2. Pinned to one core (``os.sched_setaffinity``), in this process: decoding alone
   (``trackers.video.Video``), and MediaPipe alone (``detect_for_video``, the decoding
   between its calls not counted) with 1 and with 2 faces looked for (``track`` looks
   for 2: ``face.MAX_FACES``), in CPU ms per frame (``time.process_time``: every thread
   of the process, so another job on the machine does not count) and wall ms.
3. ``faceclean track VIDEO -o take.csv`` end to end in a child pinned to the same core
   (``taskset``): its wall time and its CPU time (user + sys).

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

FPS = 30.0  # Hz
SIZE = (640, 480)  # px, width x height
LOOP = 300  # distinct rendered frames (10 s)


def render(path: Path, seconds: float) -> None:
    """Write ``seconds`` of a rendered face at FPS, SIZE to ``path`` (mp4v)."""
    import cv2

    from faceclean.channels import ARKIT52
    from faceclean.settings import mesh_file
    from faceclean.synthetic.engine import drift
    from faceclean.synthetic.head import Head
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene

    scene = dataclasses.replace(Scene.draw(5, "studio"), resolution=SIZE[1])
    renderer = Renderer(Head.load(mesh_file("ict_full.npz")), scene)
    t = np.arange(LOOP) / FPS  # s
    pose = drift(t, 12.0, 5)  # (LOOP, 3) deg
    frames = []
    for k in range(LOOP):
        w = np.zeros(len(ARKIT52))
        w[ARKIT52.index("jawOpen")] = 0.5 * np.sin(2.1 * t[k]) ** 2
        w[ARKIT52.index("mouthSmileLeft")] = w[ARKIT52.index("mouthSmileRight")] = (
            0.4 * np.sin(0.7 * t[k]) ** 2
        )
        blink = 1.0 if k % 90 in (40, 41, 42) else 0.0
        w[ARKIT52.index("eyeBlinkLeft")] = w[ARKIT52.index("eyeBlinkRight")] = blink
        img = np.zeros((SIZE[1], SIZE[0], 3), np.uint8)
        x = (SIZE[0] - SIZE[1]) // 2
        img[:, x : x + SIZE[1]] = renderer.frame(w, pose[k], k)
        frames.append(cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    order = np.concatenate([np.arange(LOOP), np.arange(LOOP)[::-1]])  # forth and back
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), FPS, SIZE)
    for k in range(int(round(seconds * FPS))):
        writer.write(frames[order[k % len(order)]])
    writer.release()


def decode(path: Path) -> dict:
    """Decoding alone, per frame."""
    from faceclean.trackers.video import Video

    cpu, wall = time.process_time(), time.perf_counter()
    with Video(path) as video:
        n = sum(1 for _ in video)
    return {"frames": n, "cpu_ms": 1e3 * (time.process_time() - cpu) / n,
            "wall_ms": 1e3 * (time.perf_counter() - wall) / n}  # fmt: skip


def mediapipe(path: Path, faces: int) -> dict:
    """MediaPipe's own cost per frame: ``detect_for_video`` alone (the decoding between
    calls not counted), ``faces`` looked for."""
    import mediapipe as mp

    from faceclean.settings import tracker_model
    from faceclean.trackers.mediapipe import landmarker
    from faceclean.trackers.video import Video

    found = n = 0
    cpu = wall = 0.0
    with landmarker(tracker_model(), video=True, blendshapes=True, pose=True,
                    faces=faces) as marker, Video(path) as video:  # fmt: skip
        for rgb, t in video:
            image = mp.Image(image_format=mp.ImageFormat.SRGB, data=rgb)
            c, w = time.process_time(), time.perf_counter()
            result = marker.detect_for_video(image, int(round(t * 1000)))
            cpu, wall = cpu + time.process_time() - c, wall + time.perf_counter() - w
            found, n = found + bool(result.face_blendshapes), n + 1
    return {"cpu_ms": 1e3 * cpu / n, "wall_ms": 1e3 * wall / n, "found": found / n}


def end_to_end(path: Path, out: Path, core: int) -> dict:
    """``faceclean track`` in a child on ``core``: wall s and CPU s (user + sys)."""
    before = os.times()
    wall = time.perf_counter()
    cmd = ["taskset", "-c", str(core), sys.executable, "-m", "faceclean", "track", str(path),
           "-o", str(out)]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - wall
    after = os.times()
    if done.returncode != 0:
        raise SystemExit(done.stderr[-2000:])
    cpu = (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )
    said = [ln for ln in done.stdout.splitlines() if ln.startswith("wrote")]
    return {"wall_s": wall, "cpu_s": cpu, "said": said[-1] if said else ""}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--core", type=int, default=0)
    a = p.parse_args()
    os.sched_setaffinity(0, {a.core})
    with tempfile.TemporaryDirectory() as tmp:
        video = Path(tmp) / "face.mp4"
        started = time.perf_counter()
        render(video, a.seconds)
        rendered = time.perf_counter() - started
        size = video.stat().st_size  # bytes
        res = {
            "video": {"seconds": a.seconds, "fps": FPS, "size": SIZE, "bytes": size},
            "render_s": rendered,
            "decode": decode(video),
            "mediapipe_1_face": mediapipe(video, 1),
            "mediapipe_2_faces": mediapipe(video, 2),
        }
        res["faceclean_track"] = end_to_end(video, Path(tmp) / "take.csv", a.core)
    res["load_average"] = os.getloadavg()
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
