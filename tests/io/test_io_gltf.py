"""glTF/GLB: a small real GLB built here with pygltflib, cleaned weights written back."""

from __future__ import annotations

import base64
import importlib.util
import json
import struct

import numpy as np
import pygltflib as g
import pytest

from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.io import load, save
from faceclean.settings import data_dir

TARGETS = ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight", "mouthSmileLeft")
N = 90  # keyframes, 30 fps


def _mesh() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(V, 3) neutral, (F, 3) faces, (T, V, 3) deltas: the ARKit mesh, or a triangle."""
    path = data_dir() / "meshes" / "arkit_reference_mesh.npz" if data_dir() else None
    if path is not None and path.is_file():
        with np.load(path, allow_pickle=False) as z:
            names = [str(n) for n in z["names"]]
            pick = [names.index(t) for t in TARGETS]
            return z["neutral_vertices"], z["faces"], z["blendshape_deltas"][pick]
    tri = np.eye(3)
    return tri, np.array([[0, 1, 2]]), np.stack([tri * 0.1 * (k + 1) for k in range(4)])


def build(path, interpolation="LINEAR", component=g.FLOAT, minmax=False) -> dict:
    """Write a GLB (or .gltf with a data URI) and say where the weights' bytes are."""
    neutral, faces, deltas = _mesh()
    times = (np.arange(N) / 30.0).astype(np.float32)
    rng = np.random.default_rng(1)
    weights = np.clip(0.5 + 0.5 * np.sin(times[:, None] * (1 + np.arange(4))), 0, 1)
    weights = weights + 0.02 * rng.standard_normal(weights.shape)  # jitter to clean
    k = 3 if interpolation == "CUBICSPLINE" else 1
    keys = np.repeat(np.clip(weights, 0, 1)[:, None, :], k, axis=1)
    if k == 3:
        keys[:, 0] = 0.25  # in-tangents
        keys[:, 2] = -0.5  # out-tangents
    dtype, scale = {g.FLOAT: ("<f4", None), g.UNSIGNED_BYTE: ("<u1", 255)}[component]
    out = keys.ravel() if scale is None else np.round(keys.ravel() * scale)
    parts = [
        faces.astype("<u4").tobytes(),
        neutral.astype("<f4").tobytes(),
        *[d.astype("<f4").tobytes() for d in deltas],
        times.tobytes(),
        out.astype(dtype).tobytes(),
        bytes(range(256)) * 3,  # an unrelated payload, e.g. an image
    ]
    views, blob = [], b""
    for data in parts:
        blob += b"\0" * (-len(blob) % 4)
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
        blob += data
    v = len(neutral)
    lo, hi = neutral.min(0).tolist(), neutral.max(0).tolist()
    accessors = [
        g.Accessor(bufferView=0, componentType=g.UNSIGNED_INT, count=faces.size, type="SCALAR"),
        g.Accessor(bufferView=1, componentType=g.FLOAT, count=v, type="VEC3", min=lo, max=hi),
    ]
    for i, d in enumerate(deltas):
        accessors.append(
            g.Accessor(bufferView=2 + i, componentType=g.FLOAT, count=v, type="VEC3",
                       min=d.min(0).tolist(), max=d.max(0).tolist())
        )  # fmt: skip
    t_acc, w_acc = len(accessors), len(accessors) + 1
    accessors.append(g.Accessor(bufferView=t_acc, componentType=g.FLOAT, count=N, type="SCALAR",
                                min=[0.0], max=[float(times[-1])]))  # fmt: skip
    w = g.Accessor(bufferView=w_acc, componentType=component, count=out.size, type="SCALAR",
                   normalized=scale is not None)  # fmt: skip
    if minmax:
        w.min, w.max = [float(out.min() / (scale or 1))], [float(out.max() / (scale or 1))]
    accessors.append(w)
    prim = g.Primitive(attributes=g.Attributes(POSITION=1), indices=0,
                       targets=[{"POSITION": 2 + i} for i in range(len(deltas))])  # fmt: skip
    mesh = g.Mesh(primitives=[prim], weights=[0.0] * 4, extras={"targetNames": list(TARGETS)})
    sampler = g.AnimationSampler(input=t_acc, output=w_acc, interpolation=interpolation)
    target = g.AnimationChannelTarget(node=0, path="weights")
    gltf = g.GLTF2(
        scene=0,
        scenes=[g.Scene(nodes=[0])],
        nodes=[g.Node(mesh=0, name="face")],
        meshes=[mesh],
        accessors=accessors,
        bufferViews=views,
        buffers=[g.Buffer(byteLength=len(blob))],
        animations=[
            g.Animation(samplers=[sampler], channels=[g.AnimationChannel(sampler=0, target=target)])
        ],
    )
    if str(path).endswith(".glb"):
        gltf.set_binary_blob(blob)
        gltf.save_binary(str(path))
    else:
        gltf.buffers[0].uri = (
            "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        )
        gltf.save_json(str(path))
    return {"view": views[w_acc], "weights": keys[:, 1 if k == 3 else 0], "keys": keys}


def _chunks(raw: bytes) -> tuple[bytes, int]:
    size = struct.unpack_from("<I", raw, 12)[0]
    return raw[20 : 20 + size], 20 + size + 8  # JSON chunk, BIN data offset


@pytest.mark.parametrize(
    "interpolation, component",
    [("LINEAR", g.FLOAT), ("STEP", g.FLOAT), ("CUBICSPLINE", g.FLOAT), ("LINEAR", g.UNSIGNED_BYTE)],
)
def test_glb_round_trip_only_weights_bytes_change(tmp_path, interpolation, component):
    src = tmp_path / "face.glb"
    info = build(src, interpolation, component)
    anim = load(src)
    assert anim.meta["format"] == "gltf" and anim.names == TARGETS
    assert anim.meta["interpolation"] == interpolation
    atol = 1e-6 if component == g.FLOAT else 0.5 / 255
    np.testing.assert_allclose(anim.values, info["weights"], atol=atol)
    np.testing.assert_allclose(anim.times, np.arange(N) / 30.0, atol=1e-6)

    same = tmp_path / "same.glb"
    save(anim, same)
    assert same.read_bytes() == src.read_bytes()  # unchanged values -> identical file

    new = np.clip(anim.values * 0.5 + 0.1, 0, 1)
    out = tmp_path / "out.glb"
    save(anim.with_values(new), out)
    a, b = src.read_bytes(), out.read_bytes()
    assert len(a) == len(b)
    json_chunk, bin_at = _chunks(a)
    assert _chunks(b)[0] == json_chunk
    lo = bin_at + info["view"].byteOffset
    hi = lo + info["view"].byteLength
    diff = np.flatnonzero(np.frombuffer(a, np.uint8) != np.frombuffer(b, np.uint8))
    assert len(diff) > 0 and diff.min() >= lo and diff.max() < hi
    back = load(out)
    np.testing.assert_allclose(back.values, new, atol=atol)
    if interpolation == "CUBICSPLINE":  # tangents kept
        keys = back.meta["gltf"].keys
        assert (keys[:, 0] == 0.25).all() and (keys[:, 2] == -0.5).all()


def test_minmax_updated_and_gltf_json_output(tmp_path):
    src = tmp_path / "face.glb"
    build(src, minmax=True)
    anim = load(src)
    new = anim.values * 0.5
    out = tmp_path / "out.gltf"
    save(anim.with_values(new), out)
    doc = json.loads(out.read_text())
    assert doc["buffers"][0]["uri"].startswith("data:application/octet-stream;base64,")
    acc = doc["accessors"][doc["animations"][0]["samplers"][0]["output"]]
    assert acc["max"][0] == pytest.approx(new.max(), abs=1e-6)
    back = load(out)
    np.testing.assert_allclose(back.values, new, atol=1e-6)
    # and .gltf in, .glb out: buffer 0 moves into the BIN chunk
    glb = tmp_path / "again.glb"
    save(back, glb)
    assert glb.read_bytes()[:4] == b"glTF"
    np.testing.assert_allclose(load(glb).values, new, atol=1e-6)


def test_gltf_with_data_uri_reads(tmp_path):
    src = tmp_path / "face.gltf"
    info = build(src)
    np.testing.assert_allclose(load(src).values, info["weights"], atol=1e-6)


@pytest.mark.skipif(
    importlib.util.find_spec("faceclean.filters.ema") is None, reason="ema not written yet"
)
def test_cli_clean_glb(tmp_path, capsys):
    src = tmp_path / "face.glb"
    build(src)
    out = tmp_path / "clean.glb"
    assert main(["clean", str(src), "-o", str(out), "--method", "ema", "--set", "tau=0.05"]) == 0
    assert "90 frames, 4 channels" in capsys.readouterr().out
    a, b = load(src), load(out)
    jitter = lambda v: np.abs(np.diff(v, 2, axis=0)).mean()  # noqa: E731
    assert jitter(b.values) < 0.5 * jitter(a.values)
    assert main(["convert", str(out), "-o", str(tmp_path / "w.csv")]) == 0
    assert load(tmp_path / "w.csv").names == TARGETS


def test_refusals(tmp_path):
    src = tmp_path / "face.glb"
    build(src)
    anim = load(src)
    with pytest.raises(FacecleanError, match="keyframe times"):
        save(
            anim.__class__(anim.times[:-1], anim.values[:-1], anim.names, anim.meta),
            tmp_path / "x.glb",
        )
    csv = tmp_path / "a.csv"
    csv.write_text("time,headYaw\n0,0.5\n")  # a take becomes a new GLB: it needs ARKit channels
    with pytest.raises(FacecleanError, match="ARKit blendshape"):
        save(load(csv), tmp_path / "y.glb")
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"glTF\x02\0\0\0\x10\0\0\0")
    with pytest.raises(FacecleanError):
        load(bad)
    empty = tmp_path / "empty.gltf"
    empty.write_text('{"asset": {"version": "2.0"}}')
    with pytest.raises(FacecleanError, match="no morph-target weight animation"):
        load(empty)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "a.csv",
        "bad.glb",
        "empty.gltf",
        "face.glb",
    ]
