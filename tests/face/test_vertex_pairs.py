"""Face meshes and the 6 vertex pairs of the distance loss."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import arkit_weights

from faceclean.errors import FacecleanError
from faceclean.face.vertex_pairs import PAIR_NAMES, load_face
from faceclean.settings import data_dir

DATA = data_dir()
MESHES = DATA / "meshes" if DATA is not None else None
needs_meshes = pytest.mark.skipif(
    MESHES is None or not (MESHES / "arkit_reference_mesh.npz").is_file(),
    reason="shared data meshes/ absent",
)
LIPS = [PAIR_NAMES.index(n) for n in ("lip_right_third", "lip_middle", "lip_left_third")]
EYE_L, EYE_R = PAIR_NAMES.index("eyelid_left"), PAIR_NAMES.index("eyelid_right")
CORNERS = PAIR_NAMES.index("mouth_corners")


@needs_meshes
@pytest.mark.parametrize("name", ["arkit_reference_mesh.npz", "ict_face_area.npz"])
def test_pairs_measure_lips_and_eyelids(name):
    face = load_face(MESHES / name)
    rest = face.distances(arkit_weights())
    jaw = face.distances(arkit_weights(jawOpen=1.0))
    blink_l = face.distances(arkit_weights(eyeBlinkLeft=1.0))
    blink_r = face.distances(arkit_weights(eyeBlinkRight=1.0))
    assert np.all(jaw[LIPS] > rest[LIPS] + 0.5)  # lips part by over half a mouth width
    assert np.all(rest[LIPS] < 0.05)  # and meet in the neutral face
    assert rest[CORNERS] == pytest.approx(1.0)  # distances in mouth widths
    assert blink_l[EYE_L] < 0.3 * rest[EYE_L]  # a blink closes its own eye ...
    assert blink_l[EYE_R] == pytest.approx(rest[EYE_R], abs=1e-3)  # ... not the other
    assert blink_r[EYE_R] < 0.3 * rest[EYE_R]
    assert np.allclose(blink_l[LIPS], rest[LIPS], atol=1e-3)
    # the thirds sit on either side of the middle, symmetric about it
    x = face.mesh.vertices[face.pairs[LIPS]].mean(axis=1)[:, 0]
    assert x[0] < x[1] < x[2] or x[0] > x[1] > x[2]
    width = np.linalg.norm(np.subtract(*face.mesh.vertices[face.pairs[CORNERS]]))
    assert abs(abs(x[0] - x[1]) - width / 6) < width / 24


@needs_meshes
def test_default_mesh_and_given_pairs():
    face = load_face()
    assert face.mesh.deltas.shape == (52, 1220, 3) and face.mesh.vertices.shape == (1220, 3)
    mine = face.pairs.copy()
    mine[0] = [0, 1]
    assert np.array_equal(load_face(pairs=mine).pairs, mine)
    with pytest.raises(FacecleanError):
        load_face(pairs=[[0, 10**6]] * 6)


def test_glb_with_morph_targets(tmp_path):
    """A tiny synthetic face as GLB: two lips, two eyelids per side, two mouth corners."""
    pygltflib = pytest.importorskip("pygltflib")
    neutral = np.array(
        [[0, 0, 0], [0, 0.001, 0], [-0.02, 0, 0], [0.02, 0, 0],  # lips, corners
         [-0.02 / 3, 0, 0], [-0.02 / 3, 0.001, 0], [0.02 / 3, 0, 0], [0.02 / 3, 0.001, 0],
         [0.03, 0.05, 0], [0.03, 0.04, 0], [-0.03, 0.05, 0], [-0.03, 0.04, 0]],  # eyes
        np.float32,
    )  # fmt: skip
    shapes = {
        "jawOpen": {0: [0, -0.03, 0], 4: [0, -0.02, 0], 6: [0, -0.02, 0]},
        "eyeBlinkLeft": {8: [0, -0.01, 0]},
        "eyeBlinkRight": {10: [0, -0.01, 0]},
        "mouthSmileLeft": {3: [0.005, 0.005, 0]},
        "mouthSmileRight": {2: [-0.005, 0.005, 0]},
    }
    blobs = [neutral.tobytes()]
    for moves in shapes.values():
        d = np.zeros_like(neutral)
        for i, v in moves.items():
            d[i] = v
        blobs.append(d.tobytes())
    n = len(neutral)
    g = pygltflib.GLTF2(
        buffers=[pygltflib.Buffer(byteLength=12 * n * len(blobs))],
        bufferViews=[
            pygltflib.BufferView(buffer=0, byteOffset=12 * n * i, byteLength=12 * n)
            for i in range(len(blobs))
        ],
        accessors=[
            pygltflib.Accessor(bufferView=i, componentType=5126, count=n, type="VEC3")
            for i in range(len(blobs))
        ],
        meshes=[
            pygltflib.Mesh(
                primitives=[
                    pygltflib.Primitive(
                        attributes=pygltflib.Attributes(POSITION=0),
                        targets=[{"POSITION": i} for i in range(1, len(blobs))],
                    )
                ],
                extras={"targetNames": [k[0].upper() + k[1:] for k in shapes]},  # any case
            )
        ],
    )
    g.set_binary_blob(b"".join(blobs))
    path = tmp_path / "face.glb"
    g.save_binary(str(path))
    face = load_face(path)
    assert sorted(map(sorted, face.pairs[LIPS].tolist())) == [[0, 1], [4, 5], [6, 7]]
    assert sorted(face.pairs[CORNERS].tolist()) == [2, 3]
    assert face.pairs[EYE_L].tolist() == [8, 9] and face.pairs[EYE_R].tolist() == [10, 11]
    d = face.distances(np.stack([arkit_weights(), arkit_weights(jawOpen=1.0)]))
    assert d[1, 1] > d[0, 1] + 0.5


@pytest.mark.filterwarnings("ignore::UserWarning")  # pygltflib warns on the bad header
def test_bad_mesh_files(tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"nope")
    with pytest.raises(FacecleanError):
        load_face(junk)
    np.savez(tmp_path / "empty.npz", x=np.zeros(3))
    with pytest.raises(FacecleanError, match="not a face mesh"):
        load_face(tmp_path / "empty.npz")
    with pytest.raises(FacecleanError, match="no such"):
        load_face(tmp_path / "absent.glb")
    (tmp_path / "bad.glb").write_bytes(b"glTF garbage")
    with pytest.raises(FacecleanError):
        load_face(tmp_path / "bad.glb")


@pytest.mark.parametrize("source", ["stylised", "arkit_reference_mesh.npz", "ict_face_area.npz"])
def test_loss_pairs_of_a_glb_face_equal_those_of_its_source(tmp_path, source):
    """One mesh type: the loss reads what the viewer reads and the GLB writer writes."""
    from faceclean.face import mesh
    from faceclean.face.vertex_pairs import loss_face

    if source == "stylised":
        face, first = mesh.stylised(), loss_face(mesh.stylised())
    else:
        if MESHES is None or not (MESHES / source).is_file():
            pytest.skip("shared data meshes/ absent")
        face, first = mesh.load(MESHES / source), load_face(MESHES / source)
    from faceclean.io import gltf_take

    glb = tmp_path / "face.glb"
    gltf_take.save_mesh(face, glb)
    again = load_face(glb)
    assert np.array_equal(again.pairs, first.pairs) and again.scale == first.scale
    w = np.random.default_rng(0).uniform(0, 1, (8, 52))
    assert np.array_equal(again.distances(w), first.distances(w))
    assert np.array_equal(again.mesh.deltas, first.mesh.deltas)
