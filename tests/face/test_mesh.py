"""The stylised face: 52 ARKit shapes that do what their names say; GLB export and reading."""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers import arkit_weights

from faceclean.channels import ARKIT52, INDEX
from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.face import mesh as facemesh
from faceclean.io import gltf_take
from faceclean.settings import data_dir

MESHES = data_dir() / "meshes" if data_dir() is not None else None
needs_meshes = pytest.mark.skipif(
    MESHES is None or not (MESHES / "arkit_reference_mesh.npz").is_file(),
    reason="../shared/data/meshes is absent",
)


@pytest.fixture(scope="module")
def face() -> facemesh.FaceMesh:
    return facemesh.stylised()


@pytest.fixture(scope="module")
def glb(face, tmp_path_factory):
    path = tmp_path_factory.mktemp("mesh") / "face.glb"
    gltf_take.save_mesh(face, path)
    return path


def _moved(face, name: str) -> np.ndarray:
    """Indices of the vertices a shape moves by more than 0.5 mm."""
    return np.flatnonzero(np.linalg.norm(face.deltas[INDEX[name]], axis=1) > 5e-4)


def test_every_arkit_channel_has_a_target(face):
    assert face.deltas.shape == (52, len(face.vertices), 3)
    assert face.present.all()
    assert np.isfinite(face.vertices).all() and np.isfinite(face.deltas).all()
    assert face.faces.max() < len(face.vertices)
    assert face.colors.shape == face.vertices.shape and 0 <= face.colors.min() <= 1


def test_left_shapes_move_the_faces_left_side(face):
    # ARKit's Left is the face's own left, +x (the viewer's right).
    for name in ("eyeBlinkLeft", "mouthSmileLeft", "browOuterUpLeft", "cheekSquintLeft"):
        moved = _moved(face, name)
        assert len(moved) and np.all(face.vertices[moved, 0] > 0), name
        mirror = _moved(face, name.replace("Left", "Right"))
        assert np.all(face.vertices[mirror, 0] < 0), name


def _distance(face, a: str, b: str, w: np.ndarray) -> float:
    v = face.pose(w)
    return float(np.linalg.norm(v[face.landmarks[a]] - v[face.landmarks[b]]))


def test_blink_closes_the_eyelid(face):
    def opening(w):
        return _distance(face, "upper_lid_left", "lower_lid_left", w)

    open_, half, shut = (opening(arkit_weights(eyeBlinkLeft=a)) for a in (0.0, 0.5, 1.0))
    assert open_ > 0.01  # m: an open eye
    assert shut < 0.15 * open_ and shut < half < open_
    assert (
        opening(arkit_weights(eyeWideLeft=1.0)) > open_ > opening(arkit_weights(eyeSquintLeft=1.0))
    )
    assert opening(arkit_weights(eyeBlinkRight=1.0)) == pytest.approx(open_)  # the other eye


def test_jaw_opens_the_mouth_and_smile_lifts_the_corners(face):
    def gap(w):
        return _distance(face, "upper_lip", "lower_lip", w)

    assert gap(arkit_weights()) < 0.003 and gap(arkit_weights(jawOpen=1.0)) > 0.02  # m
    assert gap(arkit_weights(jawOpen=1.0, mouthClose=1.0)) < gap(arkit_weights(jawOpen=1.0))
    lower_lip = _moved(face, "mouthLowerDownLeft")
    jaw = face.deltas[INDEX["jawOpen"]]
    assert np.mean(jaw[lower_lip, 1]) < -0.01  # the lower lip drops by over 1 cm
    upper_lip = np.setdiff1d(_moved(face, "mouthUpperUpLeft"), _moved(face, "jawOpen"))
    assert len(upper_lip) and np.abs(jaw[upper_lip]).max() < 1e-3  # the upper lip stays
    smile = face.deltas[INDEX["mouthSmileLeft"]]
    corner = _moved(face, "mouthSmileLeft")
    assert smile[corner, 1].max() > 0.005  # the corner rises
    brow = face.deltas[INDEX["browInnerUp"]]
    assert brow[:, 1].max() > 0.008


def test_glb_round_trips_through_pygltflib(face, glb):
    import pygltflib

    gltf = pygltflib.GLTF2().load(str(glb))
    mesh = gltf.meshes[0]
    assert mesh.extras["targetNames"] == list(ARKIT52)
    assert len(mesh.primitives[0].targets) == 52 and len(mesh.weights) == 52
    pos = gltf.accessors[mesh.primitives[0].attributes.POSITION]
    assert pos.count == len(face.vertices) and len(pos.min) == 3
    back = facemesh.load(glb)
    assert np.array_equal(back.vertices, face.vertices)
    assert np.array_equal(back.faces, face.faces)
    assert np.array_equal(back.deltas, face.deltas)
    assert np.allclose(back.colors, face.colors)
    assert back.landmarks == face.landmarks


def test_glb_is_usable_by_the_distance_loss_mesh_reader(glb):
    from faceclean.face.vertex_pairs import PAIR_NAMES, load_face

    loss_face = load_face(glb)
    d0 = loss_face.distances(arkit_weights())
    jaw = loss_face.distances(arkit_weights(jawOpen=1.0))
    blink = loss_face.distances(arkit_weights(eyeBlinkLeft=1.0, eyeBlinkRight=1.0))
    middle, eye = PAIR_NAMES.index("lip_middle"), PAIR_NAMES.index("eyelid_left")
    assert jaw[middle] > d0[middle] + 0.3  # in mouth widths
    assert blink[eye] < 0.3 * d0[eye]


@needs_meshes
def test_reads_the_shared_npz_meshes():
    ref = facemesh.load(MESHES / "arkit_reference_mesh.npz")
    assert ref.vertices.shape == (1220, 3) and ref.faces.shape == (2304, 3)
    assert ref.present.sum() == 51 and not ref.present[INDEX["tongueOut"]]
    assert ref.colors is None


def test_bad_mesh_files_are_one_line_errors(tmp_path):
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"not a glb at all")
    with pytest.raises(FacecleanError, match="bad.glb"):
        facemesh.load(bad)
    with pytest.raises(FacecleanError, match="no such"):
        facemesh.load(tmp_path / "absent.npz")
    np.savez(tmp_path / "empty.npz", x=np.zeros(3))
    with pytest.raises(FacecleanError, match="empty.npz"):
        facemesh.load(tmp_path / "empty.npz")


@pytest.mark.parametrize("faces, said", [
    (lambda f: f[:, :2], "triangles are (F, 3)"),  # pairs: read as scrambled triangles
    (lambda f: np.c_[f, f[:, :1]][: len(f) // 4 * 3], "triangles are (F, 3)"),  # quads
    (lambda f: f.reshape(-1), "triangles are (F, 3)"),  # flat
    (lambda f: f + 5000, "vertex index is outside 0..1219"),
])  # fmt: skip
def test_a_mesh_whose_faces_are_not_triangles_of_its_vertices_is_refused(tmp_path, faces, said):
    z = dict(np.load(MESHES / "arkit_reference_mesh.npz", allow_pickle=False))
    z["faces"] = faces(z["faces"])
    np.savez(tmp_path / "odd.npz", **z)
    with pytest.raises(FacecleanError, match=f"odd.npz: not a face mesh npz.*{re.escape(said)}"):
        facemesh.load(tmp_path / "odd.npz")


def test_cli_face_mesh(tmp_path, capsys):
    out = tmp_path / "face.glb"
    assert main(["face-mesh", "-o", str(out)]) == 0
    assert out.read_bytes()[:4] == b"glTF"
    assert "52 ARKit morph targets" in capsys.readouterr().out
    assert main(["face-mesh", "-o", str(tmp_path / "face.obj")]) == 2
    assert not (tmp_path / "face.obj").exists()
