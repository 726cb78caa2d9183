"""The tracker interface (faceclean.tracking): MediaPipe implements it, and the pairs engine
tracks its rendered frames through it alone, so a second tracker plugs in."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean import io, tracking
from faceclean.settings import mesh_file, tracker_model

pytest.importorskip("numba")  # the renderer's rasteriser


class Brightness:
    """A second tracker, of the interface only: a frame's mean brightness per colour as
    three scores, no landmarks; no face in every third frame. It logs what it was given."""

    names = ("red", "green", "blue")
    name = "brightness 1.0"

    def __init__(self, log: list) -> None:
        self.log, self.seen = log, 0
        log.append("open")

    def read(self, frame: np.ndarray, t: float) -> tracking.Reading | None:
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        self.log.append(t)
        self.seen += 1
        if self.seen % 3 == 0:
            return None
        return tracking.Reading(frame.reshape(-1, 3).mean(axis=0) / 255.0)

    def close(self) -> None:
        self.log.append("close")


def test_scores_are_read_in_turn_with_a_lost_face_a_row_of_nan():
    log: list = []
    tracker = Brightness(log)
    assert isinstance(tracker, tracking.Tracker)
    frames = [(np.full((4, 4, 3), 51 * k, np.uint8), k / 30) for k in range(4)]
    out = tracking.scores(tracker, frames)
    assert out.shape == (4, 3) and log == ["open", 0.0, 1 / 30, 2 / 30, 3 / 30]
    np.testing.assert_allclose(out[[0, 1, 3]], [[0.0] * 3, [0.2] * 3, [0.6] * 3])
    assert np.isnan(out[2]).all()  # no face: a missing frame, never a guess
    assert tracking.scores(tracker, []).shape == (0, 3)


@pytest.fixture(scope="module")
def head_path():
    path = mesh_file("ict_full.npz")
    if path is None or not path.is_file():
        pytest.skip("shared meshes/ict_full.npz absent")
    return path


def test_the_pairs_engine_tracks_through_the_interface(head_path, tmp_path):
    """A Worker given a tracker writes that tracker's channels and name; a fresh tracker
    per clip, each closed; MediaPipe's model is never loaded (its path is not a file)."""
    from faceclean.synthetic import engine

    log: list = []
    worker = engine.Worker(head_path, tmp_path / "no-model.task", tracker=lambda: Brightness(log))
    assert log == ["open", "close"] and worker.tracker_name == "brightness 1.0"
    log.clear()
    job = engine.Job("synth:1", "synthetic", 0.0, 1.0, seed=7, setting="studio", rate=6.0,
                     webcam=False)  # fmt: skip
    meta = worker.run(job, tmp_path)
    assert log[0] == "open" and log[-1] == "close" and log.count("open") == 1
    tracked = io.load(tmp_path / f"{job.name}.tracked.csv")
    assert tracked.names == Brightness.names and tracked.n_frames == meta["frames"] == 7
    np.testing.assert_allclose(tracked.times, log[1:-1], atol=1e-6)
    lost = ~tracked.valid
    assert list(np.flatnonzero(lost)) == [2, 5] and meta["lost"] == 2
    face = tracked.values[~lost]
    assert ((face > 0.0) & (face < 1.0)).all()  # a rendered face, neither black nor white
    assert json.loads((tmp_path / f"{job.name}.json").read_text())["tracker"] == "brightness 1.0"


def test_mediapipe_is_a_tracker_with_landmarks(head_path):
    pytest.importorskip("mediapipe")
    model = tracker_model()
    if model is None or not model.is_file():
        pytest.skip("shared models/face_landmarker.task absent")
    from faceclean.synthetic.head import Head
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene
    from faceclean.trackers.mediapipe import NAMES, Tracker

    weights = np.zeros(52)
    frame = Renderer(Head.load(head_path), Scene.draw(1, "studio")).frame(weights, np.zeros(3), 0)
    with Tracker(model) as a, Tracker(model) as b:
        assert isinstance(a, tracking.Tracker) and a.names == NAMES
        assert a.name.startswith("mediapipe ")
        reading = a.read(frame, 0.0)
        assert reading is not None and reading.pose is None  # it does not ask for the matrix
        np.testing.assert_array_equal(reading.scores, b.track(frame, 0.0))  # the same scores
        points = reading.landmarks
        assert points.shape == (478, 3)
        h, w = frame.shape[:2]
        assert (points[:, 0] > 0).all() and (points[:, 0] < w).all()  # on the picture
        assert (points[:, 1] > 0).all() and (points[:, 1] < h).all()
        assert a.read(np.full_like(frame, 90), 1 / 30) is None  # no face
