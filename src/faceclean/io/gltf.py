"""glTF 2.0 / GLB morph-target weight animations, written back into a copy of the file.

Read: the first animation channel whose target path is ``"weights"`` (animations and their
channels in file order; other weight channels and meshes are left alone). Its sampler's
input accessor gives ``times`` (N,) s, the output accessor the weights (N, M), M the
morph-target count of the target node's mesh. Channel names come from
``mesh.extras.targetNames``, else the first primitive's ``extras.targetNames``, else
``target0..``. ``LINEAR`` and ``STEP`` outputs hold N x M values; ``CUBICSPLINE`` holds
N x 3 x M (in-tangent, value, out-tangent): the values are read, the tangents kept.

Write: the source file again, with only the output accessor's value bytes replaced, in its
own component type (float, or normalised integers). Same buffer layout; tangents, other
animations, meshes, images and the JSON stay as they were; only ``min``/``max`` of the
output accessor are updated when it declares them (then the JSON is re-serialised). A NaN
keeps the original weight. GLB in, GLB out: byte for byte equal outside that accessor.
Out to ``.gltf``, the changed buffer is embedded as a base64 data URI (other URIs kept as
written, relative to the output); ``.gltf`` in, ``.glb`` out moves buffer 0 into the BIN
chunk. An animation read from a glTF file must keep its keyframe times; any other take
(Live Link CSV, CSV, JSON, NPZ) becomes a new file, the stylised face animated by it
(:mod:`faceclean.io.gltf_take`).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import pygltflib

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.io.gltf_container import COMPONENTS, accessor, count, data_uri, decode, glb, parse

# componentTypes a weights output may have: float, or normalised integers (glTF 2.0)
WEIGHT_TYPES = (
    pygltflib.FLOAT,
    pygltflib.BYTE,
    pygltflib.UNSIGNED_BYTE,
    pygltflib.SHORT,
    pygltflib.UNSIGNED_SHORT,
)


@dataclass(frozen=True, eq=False)
class Source:
    """What the writer needs: kept in ``meta["gltf"]``."""

    raw: bytes  # the whole source file
    glb: bool
    doc: dict[str, Any]  # the JSON, as parsed
    bin_offset: int | None  # file offset of the GLB BIN chunk's data
    buffers: tuple[bytes, ...]  # every buffer's bytes
    accessor: int  # the weights output accessor
    keys: np.ndarray  # (N, K, M) the output as read; K = 3 for CUBICSPLINE, else 1
    times: np.ndarray  # (N,) s
    names: tuple[str, ...]


def sniff(head: bytes) -> bool:
    return head.startswith(b"glTF") or head.lstrip().startswith(b"{")


def read(path: str | os.PathLike) -> Animation:
    """Read the first morph-weight animation channel of a .gltf or .glb file."""
    p = Path(path)
    try:
        return _read(p, *parse(p))
    except (IndexError, KeyError, TypeError, AttributeError, ValueError) as e:
        raise FacecleanError(f"{p.name}: broken glTF ({type(e).__name__}: {e})") from None


def _read(
    p: Path,
    raw: bytes,
    doc: dict,
    model: pygltflib.GLTF2,
    bin_offset: int | None,
    buffers: tuple[bytes, ...],
) -> Animation:
    glb = raw.startswith(b"glTF")

    found = [
        (anim, ch)
        for anim in model.animations
        for ch in anim.channels
        if ch.target is not None and ch.target.path == "weights" and ch.target.node is not None
    ]
    if not found:
        raise FacecleanError(f"{p.name}: no morph-target weight animation in the file")
    anim, channel = found[0]
    sampler = anim.samplers[channel.sampler]
    mesh = model.meshes[model.nodes[channel.target.node].mesh]
    m = len(mesh.primitives[0].targets or [])
    if m == 0:
        raise FacecleanError(f"{p.name}: the animated mesh has no morph targets")
    for i in (sampler.input, sampler.output):  # the JSON as written (the writer uses it)
        _raw_fields(doc, count(i, "accessor index"))
    times = _scalars(model, buffers, sampler.input)
    out = _scalars(model, buffers, sampler.output)
    k = 3 if sampler.interpolation == pygltflib.ANIM_CUBICSPLINE else 1
    if out.size != len(times) * k * m:
        raise FacecleanError(
            f"{p.name}: weights output has {out.size} values, expected {len(times)} x {k} x {m}"
        )
    keys = out.reshape(len(times), k, m)
    names = _target_names(mesh, m)
    source = Source(
        raw, glb, doc, bin_offset, buffers, sampler.output, keys.copy(), times.copy(), names
    )
    values = keys[:, 1 if k == 3 else 0, :]
    meta = {"format": "gltf", "gltf": source, "interpolation": sampler.interpolation or "LINEAR"}
    pose = _head_pose(model, buffers, anim, channel.target.node, times)
    if pose is not None:
        meta.update(pose=pose, pose_names=list(HEAD))
    return Animation(times, values, names, meta)


HEAD = ("HeadYaw", "HeadPitch", "HeadRoll")  # the angles a head node's rotation reads as


def _head_pose(
    model: pygltflib.GLTF2, buffers: tuple[bytes, ...], anim: Any, face: int, times: np.ndarray
) -> np.ndarray | None:
    """(N, 3) yaw, pitch, roll rad at ``times`` from the rotation channel of a node named
    ``head`` above the animated face (what gltf_take writes: docs/FORMATS.md), or None.
    Keys at other times are sampled by normalised linear interpolation, held at the ends."""
    from faceclean.pose import unity_angles

    parent = {c: i for i, n in enumerate(model.nodes) for c in (n.children or [])}
    above, node = set(), face
    while node in parent and len(above) < len(model.nodes):  # (a cycle cannot loop)
        node = parent[node]
        above.add(node)
    for ch in anim.channels:
        node = ch.target.node if ch.target is not None else None
        if ch.target.path != "rotation" or node not in above:
            continue
        if str(model.nodes[node].name or "").lower() != "head":
            continue
        sampler = anim.samplers[ch.sampler]
        t = accessor(model, buffers, sampler.input)[:, 0]
        q = accessor(model, buffers, sampler.output, normalized=True)
        step = 3 if sampler.interpolation == pygltflib.ANIM_CUBICSPLINE else 1
        q = q[1::3] if step == 3 else q  # the values between the tangents
        if q.shape != (len(t), 4) or not len(t) or not np.all(np.diff(t) > 0):
            raise FacecleanError("the head node's rotation keys do not match their times")
        if not np.array_equal(t, times):
            q = np.stack([np.interp(times, t, q[:, j]) for j in range(4)], axis=1)
        return unity_angles(q * np.array([1.0, -1.0, -1.0, 1.0]))  # glTF -> Unity frame
    return None


WRITE_NEEDS_PATH = True  # io.save passes the target path: its suffix picks GLB or .gltf


def write(anim: Animation, f: BinaryIO, path: str | os.PathLike | None = None) -> None:
    """Write the weights back into a copy of the source file (a take read from another
    format: a new file, see :mod:`faceclean.io.gltf_take`).

    The container is GLB when ``path`` ends in ``.glb``, JSON glTF for ``.gltf``, else the
    source's.
    """
    src = anim.meta.get("gltf")
    if not isinstance(src, Source):  # a take from another format: a new animated face
        from faceclean.io import gltf_take

        gltf_take.write(anim, f, path)
        return
    if anim.n_frames != len(src.times) or not np.array_equal(anim.times, src.times):
        raise FacecleanError("glTF output: the keyframe times changed; cannot write them back")
    keys = src.keys.copy()
    slot = 1 if keys.shape[1] == 3 else 0
    index = {n: i for i, n in enumerate(src.names)}
    for j, n in enumerate(anim.names):
        i = index.get(n)
        if i is not None:
            new = anim.values[:, j]
            keys[:, slot, i] = np.where(np.isnan(new), keys[:, slot, i], new)

    doc = json.loads(json.dumps(src.doc))  # a deep copy we may edit
    acc = doc["accessors"][src.accessor]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype, scale = COMPONENTS[acc["componentType"]]
    encoded = _encode(keys.ravel(), dtype, scale)
    buffer_i = view["buffer"]
    data = bytearray(src.buffers[buffer_i])
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride") or encoded.itemsize
    if stride == encoded.itemsize:
        data[start : start + encoded.nbytes] = encoded.tobytes()
    else:  # interleaved view
        for n, item in enumerate(_items(encoded)):
            data[start + n * stride : start + n * stride + len(item)] = item
    json_changed = False
    if "min" in acc or "max" in acc:
        decoded = decode(encoded, scale)
        acc["min"], acc["max"] = [float(decoded.min())], [float(decoded.max())]
        json_changed = (acc["min"], acc["max"]) != (
            src.doc["accessors"][src.accessor].get("min"),
            src.doc["accessors"][src.accessor].get("max"),
        )

    suffix = Path(path).suffix.lower() if path is not None else ""
    if {".glb": True, ".gltf": False}.get(suffix, src.glb):
        in_bin_chunk = "uri" not in src.doc["buffers"][buffer_i]
        if src.glb and in_bin_chunk and not json_changed:
            out = bytearray(src.raw)
            out[src.bin_offset : src.bin_offset + len(data)] = data
            f.write(bytes(out))
            return
        buffers = list(src.buffers)
        buffers[buffer_i] = bytes(data)
        f.write(_glb(doc, buffers, buffer_i))
    else:
        for i, b in enumerate(doc.get("buffers", [])):
            if i == buffer_i or "uri" not in b:  # changed, or the GLB's BIN chunk
                b["uri"] = data_uri(bytes(data) if i == buffer_i else src.buffers[i])
        f.write((json.dumps(doc, indent=2) + "\n").encode("utf-8"))


def _scalars(model: pygltflib.GLTF2, buffers: tuple[bytes, ...], i: object) -> np.ndarray:
    """(count,) float64 of a dense SCALAR accessor (normalised integers to [-1, 1] / [0, 1])."""
    acc = model.accessors[count(i, "accessor index")]
    if acc.sparse is not None or acc.bufferView is None or acc.type != "SCALAR":
        raise FacecleanError(f"accessor {i}: only dense SCALAR accessors are supported")
    if acc.componentType not in WEIGHT_TYPES:
        raise FacecleanError(f"accessor {i}: component type {acc.componentType!r} not supported")
    return accessor(model, buffers, i, normalized=True)[:, 0]


def _raw_fields(doc: dict, i: int) -> None:
    """The accessor ``i`` and its view in the document: integer fields are integers
    (pygltflib converts ``"5126"`` on its model; the writer reads the document)."""
    acc = doc["accessors"][i]
    for key in ("componentType", "count", "bufferView", "byteOffset"):
        if key in acc:
            count(acc[key], f"accessor {i}: {key}")
    view = doc["bufferViews"][acc["bufferView"]]
    for key in ("buffer", "byteOffset", "byteLength", "byteStride"):
        if key in view:
            count(view[key], f"accessor {i}: bufferView {key}")


def _encode(values: np.ndarray, dtype: str, scale: float | None) -> np.ndarray:
    if scale is None:
        return values.astype(dtype)
    info = np.iinfo(np.dtype(dtype))
    return np.clip(np.round(values * scale), info.min, info.max).astype(dtype)


def _items(encoded: np.ndarray) -> list[bytes]:
    size = encoded.itemsize
    flat = encoded.tobytes()
    return [flat[i : i + size] for i in range(0, len(flat), size)]


def _target_names(mesh: pygltflib.Mesh, m: int) -> tuple[str, ...]:
    for extras in (mesh.extras, mesh.primitives[0].extras):
        names = extras.get("targetNames") if isinstance(extras, dict) else None
        if isinstance(names, list) and len(names) == m:
            return tuple(str(n) for n in names)
    return tuple(f"target{i}" for i in range(m))


def _glb(doc: dict[str, Any], buffers: list[bytes], changed: int) -> bytes:
    """A GLB: buffer 0 becomes the BIN chunk; other changed or URI-less buffers, data URIs."""
    for i, b in enumerate(doc.get("buffers", [])):
        if i == 0:
            b.pop("uri", None)
        elif i == changed or "uri" not in b:
            b["uri"] = data_uri(buffers[i])
    return glb(doc, buffers[0] if buffers else None)
