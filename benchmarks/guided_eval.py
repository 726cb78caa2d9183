"""Guided calibration on held-out rendered faces: does a face's own script clip help?

For each face (``Scene.draw(seed, 'studio', family=...)``), render and track (MediaPipe)
the guided script performed late and slow (``performed``: a 1 s late start, then 0.8x
speed, uneven), calibrate from it (``faceclean.guided.fit.guided``), and score on the
same face's other performances: ``--seconds`` s windows of the shared iPhone takes,
rendered with the same face. Rows (MSE over the 51 MediaPipe channels, as x raw):

    shipped   the shipped MediaPipe cleaner alone
    guided    the shipped cleaner + the face's guided adaptation
    oracle    the shipped cleaner + a per-channel gain and offset fitted on the test
              performances themselves (the most a per-face level fix can do)

Renders are cached under ``--cache`` (a face's frames are a pure function of its seed,
family and the weights), so a rerun only refits. Run:

    .venv/bin/python benchmarks/guided_eval.py --faces painted:7 dressed:5 --takes 3
"""

from __future__ import annotations

import argparse
import glob
import hashlib
import json
import time
from pathlib import Path

import numpy as np

from faceclean import io, settings
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.guided.fit import guided, shipped_cleaner
from faceclean.guided.script import load

RATE = 24.0  # Hz
TAKES = "../shared/data/arkit_takes/*/*.csv"


def performed(rate: float, seconds: float, late: float = 1.0, speed: float = 0.8):
    """(take times (N,) s, script times (N,) s): a person late by ``late`` s, then at
    ``speed`` of the script's pace, uneven (+-0.12, period 7 s)."""
    tau = np.arange(int((late + seconds / (speed - 0.12) + 1.0) * rate)) / rate
    v = speed + 0.12 * np.sin(2 * np.pi * tau / 7.0)  # script s per take s
    s = np.cumsum(v) / rate
    s = np.where(tau < late, 0.0, s - np.interp(late, tau, s))
    return tau, s


def render(face: tuple[str, int], times: np.ndarray, weights: np.ndarray, cache: Path, tag: str):
    """MediaPipe's scores (N, 51) of ``weights`` (N, 52) rendered on ``face``; cached."""
    from faceclean.synthetic.tracker import NAMES

    key = hashlib.sha256(weights.tobytes() + times.tobytes()).hexdigest()[:10]
    path = cache / f"{face[0]}{face[1]}_{tag}_{key}.npz"
    if path.is_file():
        return Animation(times, np.load(path)["tracked"], NAMES)
    from faceclean.synthetic.head import Head
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene
    from faceclean.synthetic.tracker import Tracker

    head = Head.load(settings.mesh_file("ict_full.npz"))
    renderer = Renderer(head, Scene.draw(face[1], "studio", head.n_identity, family=face[0]))
    out = np.full((len(times), len(NAMES)), np.nan)
    with Tracker(settings.tracker_model()) as tracker:
        for k, t in enumerate(times):
            y = tracker.track(renderer.frame(weights[k], np.zeros(3), k), float(t))
            if y is not None:
                out[k] = y
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, tracked=out)
    return Animation(times, out, NAMES)


def window(path: str, seconds: float, start: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """(times, weights (N, 52)) ``seconds`` of a shared take from ``start`` s, at RATE."""
    anim = io.load(path)
    values, _ = anim.arkit()
    t0 = anim.times[0] + min(start, max(0.0, anim.times[-1] - anim.times[0] - seconds))
    t = np.arange(int(seconds * RATE)) / RATE
    w = [np.interp(t + t0, anim.times, np.nan_to_num(values[:, j])) for j in range(52)]
    return t, np.clip(np.stack(w, axis=1), 0.0, 1.0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--faces", nargs="+", default=["painted:7", "dressed:5"])
    p.add_argument("--takes", type=int, default=3, help="how many shared takes to test on")
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--cache", default="/tmp/faceclean-guided-cache")
    p.add_argument("--json", help="write the numbers here")
    args = p.parse_args()
    from faceclean.synthetic.tracker import NAMES

    cols = [ARKIT52.index(n) for n in NAMES]
    script = load()
    takes = sorted(glob.glob(TAKES))
    takes = [takes[int(k)] for k in np.linspace(0, len(takes) - 1, args.takes)]
    cache, rows = Path(args.cache), []
    for spec in args.faces:
        family, seed = spec.split(":")
        face = (family, int(seed))
        tau, s = performed(RATE, script.seconds)
        take = render(face, tau, script.weights(s), cache, "script")
        started = time.perf_counter()
        fit = guided(take, "mediapipe")
        fit_s = time.perf_counter() - started
        ys, truths, raws = [], [], []
        for path in takes:
            t, w = window(path, args.seconds)
            tracked = render(face, t, w, cache, Path(path).stem)
            cleaner, _ = shipped_cleaner("mediapipe", tracked.names)
            ys.append(cleaner.clean(tracked).values)
            truths.append(w[:, cols])
            raws.append(tracked.values)
        y, truth, raw = (np.concatenate(a) for a in (ys, truths, raws))
        ok = np.isfinite(y).all(axis=1) & np.isfinite(raw).all(axis=1)
        ya = fit.adjust.adapt(y, NAMES)
        oracle = np.empty_like(y)
        for j in range(y.shape[1]):  # per channel gain and offset on the test itself
            x = np.c_[y[ok, j], np.ones(ok.sum())]
            b = np.linalg.lstsq(x, truth[ok, j], rcond=None)[0]
            oracle[:, j] = np.clip(y[:, j] * b[0] + b[1], 0, 1)
        mse_raw = float(np.mean((raw[ok] - truth[ok]) ** 2))

        def score(v: np.ndarray, ok: np.ndarray = ok, truth: np.ndarray = truth) -> float:
            return float(np.mean((v[ok] - truth[ok]) ** 2)) / mse_raw  # noqa: B023

        row = {
            "face": spec,
            "seen": fit.alignment.seen,
            "prompts": len(fit.alignment.segments),
            "fit_s": round(fit_s, 3),
            "shipped": score(y),
            "guided": score(ya),
            "oracle": score(oracle),
        }
        rows.append(row)
        print(
            f"{spec:<12} prompts seen {row['seen']}/{row['prompts']}  fit {fit_s:.2f} s  "
            f"x raw: shipped {row['shipped']:.3f}  guided {row['guided']:.3f}  "
            f"oracle {row['oracle']:.3f}",
            flush=True,
        )
    mean = {k: float(np.mean([r[k] for r in rows])) for k in ("shipped", "guided", "oracle")}
    print("mean x raw: " + "  ".join(f"{k} {v:.3f}" for k, v in mean.items()))
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "mean": mean}, indent=1) + "\n")


if __name__ == "__main__":
    main()
