"""The data engine's speed: render and track a frame, on one core.

    .venv/bin/python benchmarks/tracker_bench.py

CPU seconds per frame (``time.process_time``, so a shared machine's other load does not
count) to render a frame and to track it, as frames/s, per setting. The MediaPipe
cleaner's cost against eager torch computing the same step is a row of ``faceclean
bench`` (``make bench``; its reference is faceclean.neural.map_reference).
"""

from __future__ import annotations

import json
import time

import numpy as np


def engine(frames: int = 40) -> dict:
    from faceclean.settings import mesh_file, tracker_model
    from faceclean.synthetic.engine import drift
    from faceclean.synthetic.head import Head
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene
    from faceclean.trackers.mediapipe import Tracker

    head = Head.load(mesh_file("ict_full.npz"))
    out = {}
    for setting in ("studio", "webcam", "window"):
        r = Renderer(head, Scene.draw(0, setting))
        pose = drift(np.arange(frames) / 30, 8.0, 0)
        w = np.zeros(52)
        r.frame(w, pose[0], 0)  # compile
        with Tracker(tracker_model()) as tr:
            tr.track(r.frame(w, pose[0], 0), 0.0)
            render = track = 0.0
            for k in range(1, frames):
                w[17] = 0.4 * (1 + np.sin(k / 5))
                a = time.process_time()
                f = r.frame(w, pose[k], k)
                b = time.process_time()
                tr.track(f, k / 30)
                render, track = render + b - a, track + time.process_time() - b
        n = frames - 1
        out[setting] = {"resolution": r.scene.resolution, "render_ms": 1e3 * render / n,
                        "track_ms": 1e3 * track / n, "fps": n / (render + track)}  # fmt: skip
    return out


if __name__ == "__main__":
    print(json.dumps({"engine": engine()}, indent=1))
