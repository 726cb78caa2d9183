"""synthetic/gaze.py: the eyeballs turn with the eyeLook weights, and MediaPipe sees it."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.channels import ARKIT52
from faceclean.settings import mesh_file, tracker_model
from faceclean.synthetic.gaze import DOWN_DEG, H_DEG, UP_DEG, eye_angles


def w(**kv) -> np.ndarray:
    x = np.zeros(len(ARKIT52))
    for k, v in kv.items():
        x[ARKIT52.index(k)] = v
    return x


def test_eye_angles_follow_arkits_names():
    # out is toward the eye's own side: +x (the subject's left) for the left eye
    assert eye_angles(w(eyeLookOutLeft=1), "Left") == (H_DEG, 0.0)
    assert eye_angles(w(eyeLookInRight=1), "Right") == (H_DEG, 0.0)
    assert eye_angles(w(eyeLookOutRight=0.5), "Right") == (-H_DEG / 2, 0.0)
    assert eye_angles(w(eyeLookUpLeft=1), "Left") == (0.0, UP_DEG)
    assert eye_angles(w(eyeLookDownRight=1), "Right") == (0.0, -DOWN_DEG)
    assert eye_angles(w(eyeLookUpLeft=np.nan), "Left") == (0.0, 0.0)  # missing: ahead


@pytest.fixture(scope="module")
def head():
    pytest.importorskip("numba")
    path = mesh_file("ict_full.npz")
    if path is None or not path.is_file():
        pytest.skip("shared meshes/ict_full.npz absent")
    from faceclean.synthetic.head import Head

    return Head.load(path)


def test_eyeballs_turn_only_when_asked(head):
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene

    scene = Scene.draw(3, "studio")
    eye = ~np.isnan(head.eye_angle)
    look = w(eyeLookOutLeft=1, eyeLookInRight=1)  # both eyes to the subject's left
    ahead = Renderer(head, scene).project(look, np.zeros(3))[0]
    assert np.array_equal(ahead[eye], Renderer(head, scene).project(w(), np.zeros(3))[0][eye])
    turned = Renderer(head, scene, gaze=True).project(look, np.zeros(3))[0]
    pupils = eye & (head.eye_angle < 8.0)
    # the subject's left is the picture's right (+u); the eyeballs' backs move the other way
    assert (turned[pupils, 0] - ahead[pupils, 0]).min() > 1.0  # px
    assert np.array_equal(turned[~eye], ahead[~eye])  # only the eyeballs turn


def test_mediapipe_sees_the_irises_turn(head):
    pytest.importorskip("mediapipe")
    model = tracker_model()
    if model is None or not model.is_file():
        pytest.skip("shared models/face_landmarker.task absent")
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene
    from faceclean.trackers.mediapipe import landmarks

    r = Renderer(head, Scene.draw(3, "studio"), gaze=True)

    def offset(weights: np.ndarray) -> float:
        """The left eye's iris (473) from its corners' middle (362, 263), in eye widths."""
        lm = landmarks(model, r.frame(weights, np.zeros(3), 0))[:, :2]
        inner, outer = lm[362], lm[263]
        return float((lm[473] - (inner + outer) / 2) @ (outer - inner)) / float(
            np.sum((outer - inner) ** 2)
        )

    ahead = offset(w())
    assert offset(w(eyeLookOutLeft=0.8, eyeLookInRight=0.8)) > ahead + 0.05
    assert offset(w(eyeLookInLeft=0.8, eyeLookOutRight=0.8)) < ahead - 0.05
