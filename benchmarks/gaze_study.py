"""Gaze on the track path: MediaPipe's eyeLook scores, or its iris landmarks? (issue 36, item 3)

    .venv/bin/python benchmarks/gaze_study.py [--faces 10] [--seconds 6] [--cache DIR]

Rendered faces whose eyeballs turn with known eyeLook weights (``Renderer(gaze=True)``,
synthetic/gaze.py), each a different identity and room (painted and dressed looks, the
three render settings), the head wandering, blinks and speech; every frame tracked by
MediaPipe in VIDEO mode with its 478 landmarks. The gaze: fixations of 0.3-1.2 s at
random targets (-25..25 deg across, -20..15 deg up), turning in 50 ms, both eyes together.

Estimates of the 8 eyeLook channels, each judged on faces left out of its fit (leave one
face out; nothing here fits on the face it scores):

- ``raw``: MediaPipe's eyeLook scores as they come (and through the One Euro filter);
- ``shipped``: what ``faceclean track`` writes today: the MediaPipe cleaner (tracker map)
  over the raw scores;
- ``scores, mapped``: MediaPipe's own eyeLook scores through a linear map fitted on the
  other faces (per eye: (out - in, up - down, head yaw, head pitch, 1) -> signed across and
  up, each split into its two one-sided channels);
- ``iris, mapped``: the iris landmarks: per eye the iris centre's offset from the middle of
  the eye corners along the corner axis (outward) and across it (up), over the corner
  distance, the lid opening over the same, and the head's yaw and pitch, through the same
  kind of linear map fitted on the other faces;
- ``scores and iris, mapped``: both sets of features in one map;
- ``..., One Euro``: a map's output through the One Euro filter at its defaults
  (the shipped cleaner smooths; the maps alone do not).

``--still-eyes`` renders as the pairs that trained the shipped cleaner were rendered (the
eyeballs stay ahead, the lids move): the check of why the shipped cleaner's gaze turns
around. Prints one JSON object: per method, mean over held-out faces of the MAE over the 8
channels, and the correlation of the signed across (out - in) and up (up - down) with
the truth.
"""

from __future__ import annotations

import argparse
import contextlib
import io as io_text
import json
import os
import tempfile
from pathlib import Path

import numpy as np

FPS = 30.0  # Hz
LOOKS = [f"eyeLook{d}{s}" for s in ("Left", "Right") for d in ("Out", "In", "Up", "Down")]
# MediaPipe's face mesh: per eye (the subject's), inner corner, outer corner, upper lid,
# lower lid, iris centre
MESH = {"Left": (362, 263, 386, 374, 473), "Right": (133, 33, 159, 145, 468)}
RIDGE = 1e-3  # on the standardised features


def gaze_track(seconds: float, seed: int) -> np.ndarray:
    """(N, 2) deg (across toward the subject's left, up): fixations and quick turns."""
    rng = np.random.default_rng([seed, 36])
    n = int(round(seconds * FPS))
    out = np.zeros((n, 2))
    k, here = 0, np.zeros(2)
    while k < n:
        there = np.array([rng.uniform(-25, 25), rng.uniform(-20, 15)])
        if rng.random() < 0.25:
            there[:] = 0.0  # back to straight ahead now and then
        turn = np.linspace(0, 1, 3)[1:, None]  # 2 frames (about 50 ms)
        hold = int(rng.uniform(0.3, 1.2) * FPS)
        seg = np.concatenate([here + turn * (there - here), np.repeat(there[None], hold, 0)])
        out[k : k + len(seg)] = seg[: n - k]
        k, here = k + len(seg), there
    return out


def weights_of(gaze: np.ndarray) -> np.ndarray:
    """(N, 52) ARKit weights: the gaze's eyeLook channels (gaze.py's degrees per unit)."""
    from faceclean.channels import ARKIT52
    from faceclean.synthetic.gaze import DOWN_DEG, H_DEG, UP_DEG

    w = np.zeros((len(gaze), len(ARKIT52)))
    across, up = gaze[:, 0] / H_DEG, gaze[:, 1]
    for side, outward in (("Left", across), ("Right", -across)):
        w[:, ARKIT52.index(f"eyeLookOut{side}")] = np.clip(outward, 0, 1)
        w[:, ARKIT52.index(f"eyeLookIn{side}")] = np.clip(-outward, 0, 1)
        w[:, ARKIT52.index(f"eyeLookUp{side}")] = np.clip(up / UP_DEG, 0, 1)
        w[:, ARKIT52.index(f"eyeLookDown{side}")] = np.clip(-up / DOWN_DEG, 0, 1)
    return w


def render_and_track(face: int, seconds: float, eyes: bool = True) -> dict:
    """One face's take: truth (N, 52), raw (N, 51), landmarks (N, 10, 2) px, head (N, 3)."""
    import mediapipe as mp

    from faceclean.channels import ARKIT52
    from faceclean.settings import mesh_file, tracker_model
    from faceclean.synthetic.engine import drift
    from faceclean.synthetic.head import Head
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene
    from faceclean.trackers.face import head_angles
    from faceclean.trackers.mediapipe import NAMES, landmarker

    setting = ("studio", "webcam", "window")[face % 3]
    family = ("painted", "dressed")[face % 2]
    renderer = Renderer(Head.load(mesh_file("ict_full.npz")),
                        Scene.draw(200 + face, setting, family=family), gaze=eyes)  # fmt: skip
    t = np.arange(int(round(seconds * FPS))) / FPS
    truth = weights_of(gaze_track(seconds, face))
    rng = np.random.default_rng([face, 37])
    truth[:, ARKIT52.index("jawOpen")] = 0.3 * np.sin(2 * np.pi * rng.uniform(0.5, 1.5) * t) ** 2
    blinks = rng.choice(len(t), size=max(1, len(t) // 90), replace=False)
    for b in blinks:
        for s in ("Left", "Right"):
            truth[b : b + 3, ARKIT52.index(f"eyeBlink{s}")] = 1.0
    pose = drift(t, 8.0, face)  # (N, 3) deg
    cols = [ARKIT52.index(n) for n in NAMES]
    raw = np.full((len(t), len(NAMES)), np.nan)
    marks = np.full((len(t), 10, 2), np.nan)
    head = np.full((len(t), 3), np.nan)
    ids = [i for side in ("Left", "Right") for i in MESH[side]]
    with landmarker(tracker_model(), video=True, blendshapes=True, pose=True) as marker:
        for k in range(len(t)):
            rgb = renderer.frame(truth[k], pose[k], k)
            image = mp.Image(image_format=mp.ImageFormat.SRGB, data=rgb)
            result = marker.detect_for_video(image, int(round(t[k] * 1000)))
            if not result.face_blendshapes:
                continue
            scores = {c.category_name: c.score for c in result.face_blendshapes[0]}
            raw[k] = [scores.get(n, np.nan) for n in NAMES]
            h, w = rgb.shape[:2]
            lm = result.face_landmarks[0]
            marks[k] = [(lm[i].x * w, lm[i].y * h) for i in ids]
            head[k] = head_angles(result.facial_transformation_matrixes[0])
    return {"truth": truth, "raw": raw, "marks": marks, "head": head, "cols": np.array(cols),
            "times": t, "setting": setting, "family": family}  # fmt: skip


def iris_features(marks: np.ndarray, head: np.ndarray, side: str) -> np.ndarray:
    """(N, 5): iris offset outward and up (over the corner distance), lid opening (same),
    head yaw and pitch (rad)."""
    k = 0 if side == "Left" else 5
    inner, outer, upper, lower, iris = (marks[:, k + j] for j in range(5))  # (N, 2) px
    axis = outer - inner
    width = np.linalg.norm(axis, axis=1, keepdims=True)
    e = axis / width
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)  # perpendicular; image y runs down
    n *= np.where(n[:, 1:] > 0, -1.0, 1.0)  # pointing up in the picture
    d = iris - (inner + outer) / 2
    across = (d * e).sum(1) / width[:, 0]
    up = (d * n).sum(1) / width[:, 0]
    lid = np.linalg.norm(upper - lower, axis=1) / width[:, 0]
    return np.stack([across, up, lid, head[:, 0], head[:, 1]], axis=1)


def score_features(raw: np.ndarray, head: np.ndarray, side: str) -> np.ndarray:
    """(N, 4): MediaPipe's out - in and up - down of one eye, head yaw and pitch (rad)."""
    from faceclean.trackers.mediapipe import NAMES

    def col(name: str) -> np.ndarray:
        return raw[:, NAMES.index(f"eyeLook{name}{side}")]

    return np.stack([col("Out") - col("In"), col("Up") - col("Down"), head[:, 0], head[:, 1]], 1)


def signed(truth: np.ndarray, side: str) -> np.ndarray:
    """(N, 2): out - in, up - down of one eye's truth (ARKit-52 columns)."""
    from faceclean.channels import ARKIT52

    def col(name: str) -> np.ndarray:
        return truth[:, ARKIT52.index(f"eyeLook{name}{side}")]

    return np.stack([col("Out") - col("In"), col("Up") - col("Down")], 1)


def fit(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ridge on standardised x: (mean, scale, (F + 1, 2) weights) for y (N, 2)."""
    ok = np.isfinite(x).all(1) & np.isfinite(y).all(1)
    x, y = x[ok], y[ok]
    mu, sd = x.mean(0), x.std(0) + 1e-9
    z = np.hstack([(x - mu) / sd, np.ones((len(x), 1))])
    w = np.linalg.solve(z.T @ z + RIDGE * len(z) * np.eye(z.shape[1]), z.T @ y)
    return mu, sd, w


def apply(model, x: np.ndarray) -> np.ndarray:
    mu, sd, w = model
    return np.hstack([(x - mu) / sd, np.ones((len(x), 1))]) @ w


def split(s: np.ndarray) -> np.ndarray:
    """(N, 4) out, in, up, down from (N, 2) signed across and up."""
    return np.clip(np.stack([s[:, 0], -s[:, 0], s[:, 1], -s[:, 1]], 1), 0.0, 1.0)


def shipped(take: dict) -> np.ndarray:
    """(N, 52) what `faceclean track` writes today: the MediaPipe cleaner over the raw."""
    from faceclean import io
    from faceclean.animation import Animation
    from faceclean.cli import main
    from faceclean.trackers.mediapipe import NAMES

    with tempfile.TemporaryDirectory() as tmp:
        raw, out = Path(tmp) / "raw.csv", Path(tmp) / "clean.csv"
        io.save(Animation(take["times"], take["raw"], NAMES, {"format": "livelink"}), raw)
        with contextlib.redirect_stdout(io_text.StringIO()):  # its "wrote" line: not ours
            assert main(["clean", str(raw), "-o", str(out), "--tracker", "mediapipe"]) == 0
        return io.load(out).arkit()[0]


def smooth(pred: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``pred`` (N, 52) with its eyeLook channels through the One Euro filter at its
    defaults (1.5 Hz, beta 3), as a cleaner would give them."""
    from faceclean.animation import Animation
    from faceclean.channels import ARKIT52
    from faceclean.filters.one_euro import OneEuro

    c = [ARKIT52.index(n) for n in LOOKS]
    out = pred.copy()
    out[:, c] = OneEuro(names=LOOKS).clean(Animation(times, pred[:, c], LOOKS)).values
    return out


def judge(pred: np.ndarray, truth: np.ndarray) -> dict:
    """MAE over the 8 eyeLook channels; correlation of signed across and up (both eyes)."""
    from faceclean.channels import ARKIT52

    c = [ARKIT52.index(n) for n in LOOKS]
    ok = np.isfinite(pred[:, c]).all(1)
    p, y = pred[ok], truth[ok]
    out = {"mae": float(np.abs(p[:, c] - y[:, c]).mean())}
    for j, name in enumerate(("across", "up")):
        a = np.concatenate([signed(p, s)[:, j] for s in ("Left", "Right")])
        b = np.concatenate([signed(y, s)[:, j] for s in ("Left", "Right")])
        out[f"r_{name}"] = float(np.corrcoef(a, b)[0, 1]) if a.std() > 1e-9 else 0.0
    return out


FEATURES = {  # method -> (take, side) -> (N, F) features of one eye
    "scores, mapped": lambda t, s: score_features(t["raw"], t["head"], s),
    "iris, mapped": lambda t, s: iris_features(t["marks"], t["head"], s),
    "scores and iris, mapped": lambda t, s: np.hstack(
        [score_features(t["raw"], t["head"], s), iris_features(t["marks"], t["head"], s)[:, :3]]
    ),
}


def study(takes: list[dict]) -> dict:
    from faceclean.channels import ARKIT52

    n = len(takes)
    rows: dict[str, list[dict]] = {"raw": [], "raw, One Euro": [], "shipped": []}
    for m in FEATURES:
        rows[m], rows[f"{m}, One Euro"] = [], []
    for k, take in enumerate(takes):  # leave face k out
        truth = take["truth"]
        raw52 = np.full_like(truth, np.nan)
        raw52[:, take["cols"]] = take["raw"]
        rows["raw"].append(judge(raw52, truth))
        rows["raw, One Euro"].append(judge(smooth(raw52, take["times"]), truth))
        rows["shipped"].append(judge(take["shipped"], truth))
        for method, feats in FEATURES.items():
            pred = np.full_like(truth, np.nan)
            for side in ("Left", "Right"):
                others = [takes[j] for j in range(n) if j != k]
                model = fit(np.concatenate([feats(t, side) for t in others]),
                            np.concatenate([signed(t["truth"], side) for t in others]))  # fmt: skip
                got = split(apply(model, feats(take, side)))  # (N, 4)
                for j, d in enumerate(("Out", "In", "Up", "Down")):
                    pred[:, ARKIT52.index(f"eyeLook{d}{side}")] = got[:, j]
            rows[method].append(judge(pred, truth))
            rows[f"{method}, One Euro"].append(judge(smooth(pred, take["times"]), truth))
    out = {}
    for m, rs in rows.items():
        out[m] = {key: float(np.mean([r[key] for r in rs])) for key in rs[0]}
        out[m]["per_face_mae"] = [round(r["mae"], 4) for r in rs]
    return out


def blinks(takes: list[dict]) -> dict:
    """The eyelids: eyeBlink from MediaPipe's scores, from the lid opening over the eye's
    width (MESH's lids), or both, each through a linear map fitted leaving the face out
    (features: the eye's blink score or lid opening, head pitch; clipped to [0, 1]).
    MAE over both eyeBlink channels: all frames, frames of a blink (truth > 0.5), and
    frames looking down (eyeLookDown > 0.3, no blink: the lids lower without a blink)."""
    from faceclean.channels import ARKIT52
    from faceclean.trackers.mediapipe import NAMES

    def feats(t: dict, side: str, what: str) -> np.ndarray:
        score = t["raw"][:, NAMES.index(f"eyeBlink{side}")]
        lid = iris_features(t["marks"], t["head"], side)[:, 2]
        cols = {"scores": [score], "lids": [lid], "both": [score, lid]}[what]
        return np.stack([*cols, t["head"][:, 1]], 1)

    def truth_of(t: dict, side: str) -> np.ndarray:
        return t["truth"][:, ARKIT52.index(f"eyeBlink{side}")]

    rows: dict[str, list[np.ndarray]] = {}
    for k, take in enumerate(takes):
        others = [takes[j] for j in range(len(takes)) if j != k]
        preds = {"raw": np.stack([take["raw"][:, NAMES.index(f"eyeBlink{s}")]
                                  for s in ("Left", "Right")], 1),  # fmt: skip
                 "shipped": np.stack([take["shipped"][:, ARKIT52.index(f"eyeBlink{s}")]
                                      for s in ("Left", "Right")], 1)}  # fmt: skip
        for what in ("scores", "lids", "both"):
            got = []
            for side in ("Left", "Right"):
                y = np.concatenate([truth_of(t, side) for t in others])[:, None]
                model = fit(np.concatenate([feats(t, side, what) for t in others]),
                            np.hstack([y, y]))  # fmt: skip
                got.append(np.clip(apply(model, feats(take, side, what))[:, 0], 0, 1))
            preds[f"{what}, mapped"] = np.stack(got, 1)
        y = np.stack([truth_of(take, s) for s in ("Left", "Right")], 1)  # (N, 2)
        down = np.stack([take["truth"][:, ARKIT52.index(f"eyeLookDown{s}")]
                         for s in ("Left", "Right")], 1)  # fmt: skip
        for m, p in preds.items():
            err = np.abs(p - y)
            rows.setdefault(m, []).append(np.array([
                np.nanmean(err), np.nanmean(err[y > 0.5]),
                np.nanmean(err[(down > 0.3) & (y < 0.01)])]))  # fmt: skip
    return {m: dict(zip(("mae", "mae_blinking", "mae_looking_down"),
                        np.nanmean(rs, 0).round(4).tolist(), strict=True))
            for m, rs in rows.items()}  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--faces", type=int, default=10)
    p.add_argument("--seconds", type=float, default=6.0)
    p.add_argument("--cache", default=os.path.join(tempfile.gettempdir(), "gaze_study"))
    p.add_argument("--still-eyes", action="store_true",
                   help="as the pairs render: the lids move, the eyeballs stay")  # fmt: skip
    a = p.parse_args()
    cache = Path(a.cache)
    cache.mkdir(parents=True, exist_ok=True)
    takes = []
    for face in range(a.faces):
        still = "_still" if a.still_eyes else ""
        path = cache / f"face{face}_{a.seconds:g}s{still}.npz"
        if not path.is_file():
            take = render_and_track(face, a.seconds, eyes=not a.still_eyes)
            take["shipped"] = shipped(take)
            np.savez(path, **take)
        with np.load(path) as z:
            takes.append({k: z[k] for k in z.files})
    res = {"faces": a.faces, "seconds_each": a.seconds, "eyes_turn": not a.still_eyes,
           "frames_with_a_face": int(sum(np.isfinite(t["raw"]).all(1).sum() for t in takes)),
           "frames": int(sum(len(t["times"]) for t in takes))} | study(takes)  # fmt: skip
    res["blink"] = blinks(takes)
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
