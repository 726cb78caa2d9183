"""`faceclean track` on a video against the file path (`pairs` then `clean`): the codec's effect.

    .venv/bin/python benchmarks/track_codec.py [--faces 3] [--seconds 10]

Issue 36's target: quality on rendered videos equals the file path's to within the
codec's effect, measured and stated. For each face (its own identity, room and
performance: the synthetic performer at full range, the head wandering), 30 fps:

- ``frames``: the rendered frames given to MediaPipe as they are (what ``pairs`` does:
  the renderer's own JPEG is the only compression), then the MediaPipe cleaner;
- ``frames, track's tracker``: the same frames through ``track``'s tracker (it looks for
  two faces, which changes MediaPipe's landmarks a little), no codec;
- ``mp4v``, ``vp8``, ``h264``: the same frames written as a video (OpenCV's mp4v and VP8
  writers at their defaults; H.264 by PyAV, libx264 at its default CRF 23), tracked by
  ``trackers.face.track_video`` (what ``faceclean track`` runs), then the same cleaner.

Per path: MAE over the 51 channels against the truth, raw and cleaned; and the mean
absolute difference of its raw scores from the ``frames`` path's. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import contextlib
import io as io_text
import json
import tempfile
from pathlib import Path

import numpy as np

FPS = 30.0  # Hz


def frames_of(face: int, seconds: float) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """(times (N,) s, truth (N, 52), rendered RGB frames)."""
    from faceclean.datasets.performer import perform
    from faceclean.settings import mesh_file
    from faceclean.synthetic.engine import drift
    from faceclean.synthetic.head import Head
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene

    anim = perform(seconds, 300 + face, fps=FPS, full_range=True)
    t, truth = anim.times - anim.times[0], np.nan_to_num(anim.values)
    setting = ("studio", "webcam", "window")[face % 3]
    renderer = Renderer(Head.load(mesh_file("ict_full.npz")), Scene.draw(400 + face, setting))
    pose = drift(t, 8.0, face)
    return t, truth, [renderer.frame(truth[k], pose[k], k) for k in range(len(t))]


def write(path: Path, frames: list[np.ndarray], codec: str) -> Path:
    import cv2

    h, w = frames[0].shape[:2]
    if codec == "h264":
        import av

        with av.open(str(path), "w") as out:
            stream = out.add_stream("libx264", rate=int(FPS))
            stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
            for f in frames:
                for packet in stream.encode(av.VideoFrame.from_ndarray(f, format="rgb24")):
                    out.mux(packet)
            for packet in stream.encode():
                out.mux(packet)
        return path
    fourcc = {"mp4v": "mp4v", "vp8": "VP80"}[codec]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), FPS, (w, h))
    for f in frames:
        writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    writer.release()
    return path


def cleaned(t: np.ndarray, raw: np.ndarray) -> np.ndarray:
    """(N, 52) the MediaPipe cleaner's output (``clean --tracker mediapipe``) of raw (N, 51)."""
    from faceclean import io
    from faceclean.animation import Animation
    from faceclean.cli import main
    from faceclean.trackers.mediapipe import NAMES

    with tempfile.TemporaryDirectory() as tmp:
        src, out = Path(tmp) / "raw.csv", Path(tmp) / "clean.csv"
        io.save(Animation(t, raw, NAMES, {"format": "livelink"}), src)
        with contextlib.redirect_stdout(io_text.StringIO()):  # its "wrote" line: not ours
            assert main(["clean", str(src), "-o", str(out), "--tracker", "mediapipe"]) == 0
        return io.load(out).arkit()[0]


def mae(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a).all(1) & np.isfinite(b).all(1)
    return float(np.abs(a[ok] - b[ok]).mean())


def main() -> None:
    from faceclean.channels import ARKIT52
    from faceclean.settings import tracker_model
    from faceclean.trackers.face import FaceTracker, track_video
    from faceclean.trackers.mediapipe import NAMES, Tracker

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--faces", type=int, default=3)
    p.add_argument("--seconds", type=float, default=10.0)
    a = p.parse_args()
    cols = [ARKIT52.index(n) for n in NAMES]
    rows: dict[str, list[dict]] = {}
    for face in range(a.faces):
        t, truth, frames = frames_of(face, a.seconds)
        raws = {}
        with Tracker(tracker_model()) as tracker:
            raws["frames"] = np.array([
                np.full(len(NAMES), np.nan) if (r := tracker.track(f, tk)) is None else r
                for f, tk in zip(frames, t, strict=True)])  # fmt: skip
        with FaceTracker() as tracker:  # track's own (2 faces looked for), no codec
            raws["frames, track's tracker"] = np.array([
                np.full(len(NAMES), np.nan) if (r := tracker.track(f, tk)) is None else r[0]
                for f, tk in zip(frames, t, strict=True)])  # fmt: skip
        with tempfile.TemporaryDirectory() as tmp:
            for codec in ("mp4v", "vp8", "h264"):
                ext = {"mp4v": ".mp4", "vp8": ".webm", "h264": ".mp4"}[codec]
                video = write(Path(tmp) / f"{codec}{ext}", frames, codec)
                anim = track_video(video)
                assert anim.n_frames == len(t), (codec, anim.n_frames)
                raws[codec] = anim.values
        for path, raw in raws.items():
            rows.setdefault(path, []).append({
                "raw_mae": mae(raw, truth[:, cols]),
                "clean_mae": mae(cleaned(t, raw)[:, cols], truth[:, cols]),
                "raw_vs_frames": mae(raw, raws["frames"]),
                "lost": int((~np.isfinite(raw).any(1)).sum()),
            })  # fmt: skip
    res = {"faces": a.faces, "seconds_each": a.seconds, "fps": FPS}
    for path, rs in rows.items():
        res[path] = {k: float(np.mean([r[k] for r in rs])) for k in rs[0]}
        res[path]["clean_mae_per_face"] = [round(r["clean_mae"], 4) for r in rs]
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
