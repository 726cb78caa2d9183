"""The data engine's speed and the MediaPipe cleaner's cost, side by side in one run.

    .venv/bin/python benchmarks/tracker_bench.py

1. The engine on one core: CPU seconds per frame (``time.process_time``, so a shared
   machine's other load does not count) to render a frame and to track it, as frames/s.
2. The shipped tracker map stepping one stream and 1024 streams, against eager PyTorch
   computing the same step (One Euro, the linear map over u and u - r, the blink lift, the
   deadband), p50 of repeated steps, as a ratio (the issue-19 bar: <= 0.4x one stream,
   <= 1.0x at 1024).
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
    from faceclean.synthetic.tracker import Tracker

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


def cleaner(steps: int = 300) -> dict:
    import torch

    from faceclean.learned.tracker_map import TrackerMap
    from faceclean.settings import MODELS

    torch.set_num_threads(1)
    res = {}
    for s in (1, 1024):
        tm = TrackerMap(model=MODELS / "mediapipe.npz")
        a = {k: torch.tensor(v) for k, v in tm.weights.arrays.items()}
        rng = np.random.default_rng(0)
        x = rng.uniform(0, 0.5, (steps, s, len(tm.names)))
        ours = []
        for i in range(steps):
            t0 = time.perf_counter()
            last = tm.step(x[i], np.full(s, i / 30))
            ours.append(time.perf_counter() - t0)
        # eager torch, the same step: One Euro, m = A u + B (u - r) + c + d (x - u)_own, the
        # lift, the deadband
        band = torch.tensor(float(tm.weights.config.get("deadband", 0.0)))
        lo = torch.tensor(np.flatnonzero(tm.weights.arrays["lift_gain"] > 0))
        li = torch.tensor([tm.weights.inputs.index(tm.weights.outputs[j]) for j in lo.tolist()])
        gain, knee = a["lift_gain"][lo], a["lift_knee"][lo]
        scale = float(tm.weights.config.get("detail_scale", 1.0))
        gain_d = a["detail"] * scale if "detail" in a else None  # the gains as they run
        do = torch.tensor(np.flatnonzero(tm.weights.arrays.get("detail", np.zeros(1))))
        di = torch.tensor([tm.weights.inputs.index(tm.weights.outputs[j]) for j in do.tolist()])
        y = torch.tensor(x[0])
        prev = torch.clamp(y @ a["a"].T + a["c"], 0, 1)  # the first frame's output (r = u)
        edx = torch.zeros_like(y)
        r = y.clone()
        topped = bool(tm.weights.config.get("lift_top", False))
        top = torch.full((s, len(lo)), -np.inf, dtype=torch.float64)  # the largest lift so far
        ref = []
        with torch.no_grad():
            for i in range(1, steps):
                xi = torch.tensor(x[i])
                t0 = time.perf_counter()
                dt = 1 / 30
                ad = 1 / (1 + 1 / (2 * np.pi * a["d_cutoff"] * dt))
                edx = edx + ad * ((xi - y) / dt - edx)
                fc = a["min_cutoff"] + a["beta"] * edx.abs()
                y = y + (1 / (1 + 1 / (2 * np.pi * fc * dt))) * (xi - y)
                r = torch.minimum(r, y)
                out = y @ a["a"].T + (y - r) @ a["b"].T + a["c"]
                if len(do):
                    out[:, do] += gain_d[do] * (xi[:, di] - y[:, di])
                out = torch.clamp(out, 0, 1)
                if len(lo):  # m_j = max(m_j, clip(l / max(1, top), 0, 1)), l = g (u_j - r_j - k)
                    lift = gain * (y[:, li] - r[:, li] - knee)
                    if topped:
                        top = torch.maximum(top, lift)
                        lift = lift / torch.clamp(top, min=1.0)
                    lift = torch.clamp(lift, 0, 1)
                    out[:, lo] = torch.maximum(out[:, lo], lift)
                out = out - torch.clamp(out - prev, -band, band)
                prev = out
                ref.append(time.perf_counter() - t0)
        # the reference computes what the cleaner computes (its last frame, to rounding)
        np.testing.assert_allclose(out.numpy(), last, atol=1e-9)
        p_ours, p_ref = float(np.median(ours[10:])), float(np.median(ref[10:]))
        res[s] = {
            "numpy_us": 1e6 * p_ours / s,
            "torch_us": 1e6 * p_ref / s,
            "ratio": p_ours / p_ref,
        }
        del out
    return res


if __name__ == "__main__":
    print(json.dumps({"engine": engine(), "tracker_map": cleaner()}, indent=1))
