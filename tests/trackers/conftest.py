"""Rendered faces written as real video files, once per session: the tracker's inputs.

``face_video``: an mp4 (mp4v, 30 fps) of a rendered head turning and opening its jaw,
with ``BLANK`` frames black (no face: missing rows). ``two_faces``: two rendered people
in one picture. ``vfr_video``: the same faces at
irregular times (``VFR_TIMES``), written by PyAV with explicit timestamps. Each needs
the renderer (numba), MediaPipe's model and the shared head mesh, or skips saying so.
"""

from __future__ import annotations

import numpy as np
import pytest

N_FRAMES = 30
BLANK = (12, 13, 14)  # black frames: no face
YAW = 20.0  # deg, the renderer's yaw (+: the face turns to the subject's left)
VFR_TIMES = np.array([0, 33, 66, 150, 170, 300, 310, 420, 500, 533, 566, 700, 733, 766,
                      800, 900, 933, 966, 1000, 1033]) / 1000.0  # fmt: skip


def yaw_of(i: int) -> float:
    """Renderer yaw (deg) of frame i: +YAW for the first third, -YAW for the last, 0 between."""
    return YAW if i < N_FRAMES // 3 else (-YAW if i >= 2 * N_FRAMES // 3 else 0.0)


@pytest.fixture(scope="session")
def rendered():
    """(N_FRAMES, H, W, 3) uint8 RGB rendered faces."""
    pytest.importorskip("numba")
    pytest.importorskip("mediapipe")
    pytest.importorskip("cv2")
    from faceclean import settings

    mesh = settings.mesh_file("ict_full.npz")
    if mesh is None or not mesh.is_file() or settings.tracker_model() is None:
        pytest.skip("the shared head mesh or MediaPipe's model is absent")
    from faceclean.channels import ARKIT52
    from faceclean.synthetic.head import Head
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene

    renderer = Renderer(Head.load(mesh), Scene.draw(3, "studio"))
    frames = []
    for i in range(N_FRAMES):
        w = np.zeros(len(ARKIT52))
        w[ARKIT52.index("jawOpen")] = 0.6 * np.sin(i / 3.0) ** 2
        frames.append(renderer.frame(w, np.array([yaw_of(i), 0.0, 0.0]), i))
    return np.array(frames)


def write_video(path, frames, fps: float, fourcc: str = "mp4v", blank=()) -> str:
    """``frames`` (N, H, W, 3) RGB to ``path`` by OpenCV's VideoWriter; ``blank``: black."""
    import cv2

    h, w = frames.shape[1:3]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h))
    assert writer.isOpened(), f"OpenCV cannot write {fourcc} here"
    for i, f in enumerate(frames):
        writer.write(np.zeros_like(f) if i in blank else cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    writer.release()
    return str(path)


def write_vfr(path, frames, times) -> str:
    """``frames`` at ``times`` (s) by PyAV (H.264, a 1 ms time base): variable frame rate."""
    import fractions

    av = pytest.importorskip("av")
    h, w = frames.shape[1:3]
    with av.open(str(path), "w") as out:
        stream = out.add_stream("libx264", rate=1000)
        stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
        stream.time_base = fractions.Fraction(1, 1000)
        for f, t in zip(frames, times, strict=True):
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(f), format="rgb24")
            frame.pts, frame.time_base = int(round(t * 1000)), stream.time_base
            for packet in stream.encode(frame):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    return str(path)


def two_jaws(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(n,) jawOpen of face A (left, the larger at first) and of face B (right), in
    opposite phase: tracking the wrong face shows as a negative correlation."""
    i = np.arange(n)
    return 0.6 * np.sin(i / 3.0) ** 2, 0.6 * np.cos(i / 3.0) ** 2


@pytest.fixture(scope="session")
def two_faces(rendered):
    """(N_FRAMES, 360, 660, 3) RGB: two people side by side. A (left) is a 300 px square
    throughout (its face about 100 px wide); B (right, another identity and room, framed
    closer) grows from 110 to 330 px (its face from about 60 to 180 px), larger than A
    from about a third of the way on. Needs what ``rendered`` needs."""
    import cv2

    from faceclean import settings
    from faceclean.channels import ARKIT52
    from faceclean.synthetic.head import Head
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene

    head = Head.load(settings.mesh_file("ict_full.npz"))
    jaw_a, jaw_b = two_jaws(N_FRAMES)
    people = [Renderer(head, Scene.draw(3, "studio")), Renderer(head, Scene.draw(11, "studio"))]
    frames = np.full((N_FRAMES, 360, 660, 3), 90, np.uint8)
    for i in range(N_FRAMES):
        grown = 110 + 220 * i // N_FRAMES  # px, B's square
        for renderer, jaw, size, x in ((people[0], jaw_a[i], 300, 5),
                                       (people[1], jaw_b[i], grown, 320)):  # fmt: skip
            w = np.zeros(len(ARKIT52))
            w[ARKIT52.index("jawOpen")] = jaw
            img = cv2.resize(renderer.frame(w, np.zeros(3), i), (size, size))
            frames[i, 15 : 15 + size, x : x + size] = img  # px: (row, column) offsets
    return frames


@pytest.fixture(scope="session")
def face_video(rendered, tmp_path_factory) -> str:
    return write_video(tmp_path_factory.mktemp("video") / "face.mp4", rendered, 30, blank=BLANK)


@pytest.fixture(scope="session")
def vfr_video(rendered, tmp_path_factory) -> str:
    frames = rendered[: len(VFR_TIMES)]
    return write_vfr(tmp_path_factory.mktemp("vfr") / "vfr.mp4", frames, VFR_TIMES)
