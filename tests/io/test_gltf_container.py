"""The one glTF container reader and GLB writer (io/gltf_container.py): byte layout, the
accessor reader's cases, and hostile accessors refused in one line by every reader."""

from __future__ import annotations

import warnings

import numpy as np
import pygltflib as g
import pytest

from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.io.gltf_container import accessor, glb, parse


def test_glb_layout_pads_both_chunks():
    out = glb({"asset": {"version": "2.0"}}, b"\x01\x02\x03")
    assert out == (
        b"glTF\x02\x00\x00\x00\x3c\x00\x00\x00"  # magic, version 2, 60 bytes
        b'\x1c\x00\x00\x00JSON{"asset":{"version":"2.0"}} '  # 27 + 1 space
        b"\x04\x00\x00\x00BIN\x00\x01\x02\x03\x00"  # 3 + 1 zero
    )
    assert glb({}, None) == b"glTF\x02\x00\x00\x00\x18\x00\x00\x00\x04\x00\x00\x00JSON{}  "


def _model(accessors: list[dict], views: list[dict], data: bytes):
    doc = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": len(data)}],
           "bufferViews": views, "accessors": accessors}  # fmt: skip
    with warnings.catch_warnings():  # dataclasses_json warns on absent optional fields
        warnings.simplefilter("ignore")
        return g.GLTF2.from_dict(doc), (data,)


def test_accessor_strided_sparse_and_normalised():
    data = np.arange(8, dtype="<f4").tobytes() + bytes([1, 3]) + bytes([0, 255]) + b"\0" * 4
    views = [
        {"buffer": 0, "byteOffset": 0, "byteLength": 32, "byteStride": 16},  # 2 of 4 floats
        {"buffer": 0, "byteOffset": 32, "byteLength": 2},  # sparse indices
        {"buffer": 0, "byteOffset": 34, "byteLength": 2},  # normalised bytes
    ]
    vec2 = {"bufferView": 0, "byteOffset": 4, "componentType": g.FLOAT, "count": 2, "type": "VEC2"}
    sparse = {
        "componentType": g.UNSIGNED_BYTE, "count": 4, "type": "SCALAR", "normalized": True,
        "sparse": {"count": 2, "indices": {"bufferView": 1, "componentType": g.UNSIGNED_BYTE},
                   "values": {"bufferView": 2}},
    }  # fmt: skip
    model, buffers = _model([vec2, sparse], views, data)
    assert accessor(model, buffers, 0).tolist() == [[1.0, 2.0], [5.0, 6.0]]
    assert accessor(model, buffers, 1)[:, 0].tolist() == [0.0, 0.0, 0.0, 1.0]
    raw = accessor(model, buffers, 1, normalized=False)
    assert raw.dtype == np.uint8 and raw[:, 0].tolist() == [0, 0, 0, 255]


@pytest.mark.parametrize(
    "change, want",
    [({"count": 3}, "runs past the end of its buffer"),
     ({"byteOffset": 8}, "runs past the end of its buffer"),
     ({"byteOffset": -4}, "not a non-negative integer"),
     ({"componentType": 5130}, "component type 5130 not supported"),
     ({"type": "MAT4"}, "type 'MAT4' not supported"),
     ({"bufferView": 7}, "list index out of range"),  # callers: 'broken glTF (...)'
     ({"sparse": {"count": 1, "indices": {"bufferView": 0, "componentType": g.UNSIGNED_INT},
                  "values": {"bufferView": 0}}}, "sparse index past its 2 elements")],
)  # fmt: skip
def test_accessor_refuses_a_hostile_accessor(change, want):
    data = np.array([9, 1, 2, 3], "<u4").tobytes()
    acc = {"bufferView": 0, "componentType": g.FLOAT, "count": 2, "type": "VEC2", **change}
    model, buffers = _model([acc], [{"buffer": 0, "byteLength": 16}], data)
    with pytest.raises((FacecleanError, IndexError), match=want):
        accessor(model, buffers, 0)


def _tamper(path, pick) -> None:
    """Rewrite a GLB with one accessor's count one past its buffer's end."""
    _, doc, _, _, buffers = parse(path)
    acc = doc["accessors"][pick(doc)]
    acc["count"] += len(buffers[0])
    path.write_bytes(glb(doc, buffers[0]))


def test_every_glb_reader_refuses_an_accessor_past_its_buffer(tmp_path, capsys):
    take = tmp_path / "take.glb"
    assert main(["synth", "-o", str(tmp_path / "s.csv"), "--seed", "1"]) == 0
    assert main(["convert", str(tmp_path / "s.csv"), "-o", str(take)]) == 0
    face = tmp_path / "face.glb"
    assert main(["face-mesh", "-o", str(face)]) == 0
    capsys.readouterr()
    _tamper(take, lambda doc: doc["animations"][0]["samplers"][0]["input"])
    _tamper(face, lambda doc: doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"])
    for argv in (["info", str(take)],
                 ["convert", str(tmp_path / "s.csv"), "-o", str(tmp_path / "o.glb"),
                  "--mesh", str(face)]):  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "runs past the end of its buffer" in err[0], err
    assert not (tmp_path / "o.glb").exists()
