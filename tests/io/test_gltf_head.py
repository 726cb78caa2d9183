"""A Live Link take's head rotation as a turning ``head`` node in the GLB, checked by the
real importers of tests/importers (Khronos validator, three.js, Blender when installed)."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from helpers import IMPORTERS
from scipy.spatial.transform import Rotation
from test_gltf_take import _node, needs_blender, needs_three, needs_validator

from faceclean.animation import Animation
from faceclean.channels import ARKIT52, INDEX, POSE
from faceclean.cli import main
from faceclean.io import gltf_take, load
from faceclean.pose import gltf_quaternion

N = 60  # frames at 30 fps


def _ypr() -> np.ndarray:
    """(N, 3) rad: the head turns 40 degrees left and right, nods a little, rolls."""
    t = np.arange(N) / 30.0
    return np.stack([0.7 * np.sin(2 * t), 0.2 * np.sin(3 * t), 0.1 * np.cos(t)], axis=1)


@pytest.fixture(scope="module")
def glb(tmp_path_factory):
    folder = tmp_path_factory.mktemp("head")
    v = np.zeros((N, 52))
    v[:, INDEX["jawOpen"]] = np.linspace(0, 1, N)
    pose = np.zeros((N, 9))
    pose[:, :3] = _ypr()
    anim = Animation(np.arange(N) / 30.0, v, ARKIT52, {"pose": pose, "pose_names": POSE})
    src = folder / "take.csv"
    from faceclean.io import save

    save(anim, src, fmt="livelink")
    out = folder / "take.glb"
    assert main(["convert", str(src), "-o", str(out)]) == 0
    return out


def _want() -> np.ndarray:
    return gltf_quaternion(_ypr())


def test_the_head_node_turns_with_the_take(glb):
    from faceclean.io import gltf_container

    _, doc, *_ = gltf_container.parse(glb)  # the JSON chunk, parsed
    nodes = {n["name"]: i for i, n in enumerate(doc["nodes"])}
    head = doc["nodes"][nodes["head"]]
    assert head["children"] == [nodes["face"]] and doc["scenes"][0]["nodes"] == [nodes["head"]]
    np.testing.assert_allclose(head["translation"], gltf_take.PIVOT)
    [anim] = doc["animations"]
    paths = {(c["target"]["node"], c["target"]["path"]) for c in anim["channels"]}
    assert paths == {(nodes["face"], "weights"), (nodes["head"], "rotation")}
    q = np.abs(np.sum(gltf_take.head_rotations(load_take(glb)) * _want(), axis=1))
    assert q.min() > 1 - 1e-6  # each key the same rotation (up to sign)
    back = load(glb)  # the weights still read back as the take
    np.testing.assert_allclose(back.channel("jawOpen"), np.linspace(0, 1, N), atol=1e-6)


def test_the_head_reads_back_as_head_angles(glb, tmp_path):
    back = load(glb)
    assert back.meta["pose_names"] == ["HeadYaw", "HeadPitch", "HeadRoll"]
    np.testing.assert_allclose(back.meta["pose"], _ypr(), atol=2e-6)  # float32 keys
    # a GLB to Live Link CSV carries the head; cleaning it moves the angles, not the sign
    out = tmp_path / "back.csv"
    assert main(["convert", str(glb), "-o", str(out)]) == 0
    csv = load(out)
    names = list(csv.meta["pose_names"])
    got = csv.meta["pose"][:, [names.index(n) for n in ("HeadYaw", "HeadPitch", "HeadRoll")]]
    np.testing.assert_allclose(got, _ypr(), atol=2e-6)


def test_a_face_without_a_head_node_reads_no_head_angles(tmp_path):
    out = tmp_path / "plain.glb"
    from faceclean.io import save

    save(Animation(np.arange(3) / 30, np.zeros((3, 1)), ["jawOpen"]), out)
    assert "pose" not in load(out).meta


def test_a_missing_angle_holds_and_keys_stay_in_one_hemisphere():
    ypr = _ypr()
    pose = np.zeros((N, 9))
    pose[:, :3] = ypr
    pose[5, :3] = np.nan
    pose[30:, 0] += np.pi  # a turn past the back: the quaternion's sign would flip
    anim = Animation(np.arange(N) / 30, np.zeros((N, 1)), ["jawOpen"])
    anim.meta.update(pose=pose, pose_names=POSE)
    q = gltf_take.head_rotations(anim)
    np.testing.assert_allclose(q[5], q[4])  # held
    assert (np.sum(q[1:] * q[:-1], axis=1) > 0).all()  # the short way between keys


def load_take(glb):
    """The take the GLB was made from (its CSV beside it)."""
    return load(glb.with_name("take.csv"))


def test_takes_without_head_angles_have_no_head_node(tmp_path):
    anim = Animation(np.arange(3) / 30, np.zeros((3, 1)), ["jawOpen"])
    doc, _, _ = gltf_take.document(gltf_take_mesh(), anim)
    assert [n["name"] for n in doc["nodes"]] == ["face"]
    assert len(doc["animations"][0]["channels"]) == 1


def gltf_take_mesh():
    from faceclean.face.mesh import stylised

    return stylised()


@needs_validator
def test_khronos_validator_finds_no_issue_with_the_head(glb):
    report = _node("validate_gltf.cjs", glb)
    issues = report["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"][:5]


@needs_three
def test_three_js_turns_the_head(glb):
    got = _node("load_gltf.mjs", glb)
    [clip] = got["clips"]
    tracks = {t["name"]: t for t in clip["tracks"]}
    assert set(tracks) == {"face.morphTargetInfluences", "head.quaternion"}
    q = np.reshape(tracks["head.quaternion"]["values"], (-1, 4))
    np.testing.assert_allclose(tracks["head.quaternion"]["times"], np.arange(N) / 30, atol=1e-6)
    dots = np.abs(np.sum(q * _want(), axis=1))
    assert dots.min() > 1 - 1e-6
    # a positive yaw turns the glTF face (+Z forward) towards -X: its right, as in Unity
    turned = Rotation.from_quat(q[np.argmax(_ypr()[:, 0])]).apply([0.0, 0.0, 1.0])
    assert turned[0] < -0.5


@needs_blender
def test_blender_imports_the_head_rotation(glb, tmp_path):
    out = tmp_path / "blender.json"
    script = IMPORTERS / "blender_gltf.py"
    done = subprocess.run(
        ["blender", "-b", "--factory-startup", "--python", str(script), "--", str(glb), str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0 and out.is_file(), done.stdout[-2000:] + done.stderr[-2000:]
    got = json.loads(out.read_text())
    [head] = [o for o in got["objects"] if o["object"] == "head"]
    rot = [c for c in head["fcurves"] if c["path"] == "rotation_quaternion"]
    assert len(rot) == 4 and all(len(c["keys"]) == N for c in rot)
    w = np.array([k[1] for k in rot[0]["keys"]])  # Blender's w, its first component
    np.testing.assert_allclose(np.abs(w), np.abs(_want()[:, 3]), atol=1e-4)
