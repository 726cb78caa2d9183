"""The renderer and the tracker in the loop, on the shared ICT head and MediaPipe's model."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.settings import mesh_file, tracker_model

pytest.importorskip("numba")
mp = pytest.importorskip("mediapipe")

from faceclean.synthetic.head import Head  # noqa: E402
from faceclean.synthetic.raster import rasterise  # noqa: E402
from faceclean.synthetic.render import Renderer  # noqa: E402
from faceclean.synthetic.scene import SETTINGS, Scene  # noqa: E402
from faceclean.trackers.mediapipe import NAMES, Tracker  # noqa: E402


@pytest.fixture(scope="module")
def head():
    path = mesh_file("ict_full.npz")
    if path is None or not path.is_file():
        pytest.skip("shared meshes/ict_full.npz absent")
    return Head.load(path)


@pytest.fixture(scope="module")
def model():
    path = tracker_model()
    if path is None or not path.is_file():
        pytest.skip("shared models/face_landmarker.task absent")
    return path


def w(**kv) -> np.ndarray:
    x = np.zeros(52)
    for k, v in kv.items():
        x[ARKIT52.index(k)] = v
    return x


def test_the_z_buffer_keeps_the_nearer_triangle():
    xy = np.array([[2, 2], [30, 2], [2, 30], [2, 2], [30, 2], [2, 30]], np.float32)
    depth = np.array([5, 5, 5, 1, 1, 1], np.float32)
    colour = np.array([[1, 0, 0]] * 3 + [[0, 1, 0]] * 3, np.float32)
    for order in ([[0, 1, 2], [3, 4, 5]], [[3, 4, 5], [0, 1, 2]]):
        img, covered = rasterise(xy, depth, colour, np.array(order, np.int32), 32)
        assert covered[5, 5] and not covered[30, 30]
        np.testing.assert_allclose(img[5, 5], [0, 1, 0])  # the near one, whatever the order


def test_a_frame_is_a_pure_function_of_scene_weights_pose_and_index(head):
    scene = Scene.draw(3, "studio")
    a = Renderer(head, scene).frame(w(jawOpen=0.4), np.array([5.0, 0, 0]), 7)
    b = Renderer(head, Scene.draw(3, "studio")).frame(w(jawOpen=0.4), np.array([5.0, 0, 0]), 7)
    c = Renderer(head, scene).frame(w(jawOpen=0.4), np.array([5.0, 0, 0]), 8)  # new noise
    assert a.shape == (scene.resolution, scene.resolution, 3) and a.dtype == np.uint8
    np.testing.assert_array_equal(a, b)
    assert np.abs(a.astype(int) - c).mean() > 0.1
    assert Scene.draw(4, "studio").identity != scene.identity


def test_settings_differ_and_unknown_ones_are_refused():
    assert {Scene.draw(0, s).setting for s in SETTINGS} == set(SETTINGS)
    with pytest.raises(FacecleanError, match="unknown render setting"):
        Scene.draw(0, "moon")


def test_mediapipe_reads_the_render_and_loses_an_empty_frame(head, model):
    r = Renderer(head, Scene.draw(1, "studio"))
    with Tracker(model) as tr:
        rest = tr.track(r.frame(w(), np.zeros(3), 0), 0.0)
        jaw = tr.track(r.frame(w(jawOpen=0.8), np.zeros(3), 1), 1 / 30)
        blink = tr.track(r.frame(w(eyeBlinkLeft=1.0, eyeBlinkRight=1.0), np.zeros(3), 2), 2 / 30)
        empty = tr.track(np.full((256, 256, 3), 90, np.uint8), 3 / 30)
    assert rest is not None and rest.shape == (len(NAMES),) and "tongueOut" not in NAMES
    j, b = NAMES.index("jawOpen"), NAMES.index("eyeBlinkLeft")
    assert jaw[j] > rest[j] + 0.3  # an open jaw reads as one
    assert blink[b] > rest[b] + 0.2  # closed eyes read as (weaker) blinks
    assert empty is None  # a lost face is a missing frame


def test_bad_mesh_and_model_files_are_one_line(tmp_path):
    bad = tmp_path / "m.npz"
    np.savez(bad, neutral_vertices=np.zeros((3, 3)))
    with pytest.raises(FacecleanError, match="not an ICT head mesh"):
        Head.load(bad)
    junk = tmp_path / "face_landmarker.task"
    junk.write_bytes(b"not a model" * 100)
    with pytest.raises(FacecleanError, match="not a usable face landmarker model"):
        Tracker(junk)
    with pytest.raises(FacecleanError, match="no such tracker model file"):
        Tracker(tmp_path / "absent.task")


def _bundle(path, members: dict[str, bytes]) -> None:
    import zipfile

    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)


TFL = b"\x1c\x00\x00\x00TFL3" + bytes(100)  # a TFLite flatbuffer's first bytes


@pytest.mark.parametrize(
    ("members", "said"),
    [
        ({"readme.txt": b"not a model"}, "no face_detector.tflite in the bundle"),
        (
            {"face_detector.tflite": TFL, "face_landmarks_detector.tflite": TFL},
            "no face_blendshapes.tflite",
        ),
        (
            {
                "face_detector.tflite": TFL,
                "face_landmarks_detector.tflite": b"x" * 50,
                "face_blendshapes.tflite": TFL,
            },
            "face_landmarks_detector.tflite is not a TFLite model",
        ),
    ],
)
def test_a_task_zip_without_its_models_is_refused_before_mediapipe(tmp_path, members, said):
    task = tmp_path / "face_landmarker.task"
    _bundle(task, members)
    with pytest.raises(FacecleanError, match=said) as e:
        Tracker(task)
    assert str(e.value).startswith(f"{task}: not a usable face landmarker model")


def _ict(**changes) -> dict:
    """The smallest arrays under every key Head.load asks for (not a renderable head)."""
    d = {
        "neutral_vertices": np.zeros((4, 3), np.float32),
        "triangles": np.array([[0, 1, 2], [1, 2, 3]], np.int32),
        "triangle_material": np.zeros(2, np.int8),
        "material_names": np.array(["M_Face"]),
        "arkit_names": np.array(["jawOpen"]),
        "arkit_deltas": np.zeros((1, 4, 3), np.float16),
        "identity_modes": np.zeros((2, 4, 3), np.float16),
        "landmark_vertices": np.zeros(68, np.int32),
    }
    d.update(changes)
    return d


@pytest.mark.parametrize(
    ("key", "value", "said"),
    [
        ("neutral_vertices", np.nan, "'neutral_vertices' holds NaN or infinite values"),
        ("arkit_deltas", np.inf, "'arkit_deltas' holds NaN or infinite values"),
        ("identity_modes", 60000.0, "'identity_modes' reaches 6e\\+04 cm"),
    ],
)
def test_a_head_mesh_with_non_finite_geometry_is_refused(tmp_path, key, value, said):
    d = _ict()
    d[key] = np.full_like(d[key], value)
    np.savez(tmp_path / "head.npz", **d)
    with pytest.raises(FacecleanError, match=said):
        Head.load(tmp_path / "head.npz")


def test_a_head_mesh_whose_array_claims_gigabytes_is_refused_unread(tmp_path):
    import struct
    import zipfile

    header = "{'descr': '<f4', 'fortran_order': False, 'shape': (200000000, 3), }".ljust(118)
    npy = b"\x93NUMPY\x01\x00" + struct.pack("<H", 119) + (header + "\n").encode()
    with zipfile.ZipFile(tmp_path / "head.npz", "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("neutral_vertices.npy", npy + bytes(1 << 20))
    with pytest.raises(FacecleanError, match=r"claims \(200000000, 3\) float32"):
        Head.load(tmp_path / "head.npz")
