"""Any take as a new glTF 2.0 file: a face mesh, its 52 ARKit morph targets, and the take
as the mesh's morph-weight animation (what Blender, Unity's glTFast and three.js import as
shape keys / blend shapes / morph targets with one animation clip).

Layout: one scene, one node ``face`` with one mesh; the first primitive carries 52 dense
POSITION morph targets in canonical ARKit order (a channel the mesh lacks is an all-zero
target), named in ``mesh.extras.targetNames``. One animation (named after the take) with
one ``LINEAR`` sampler: input the keyframe times (K,) s, output the weights (K x 52).

Keyframes, the rule chosen for what glTF cannot hold:
- times start at 0 at the take's first frame (``t - t[0]``), so the clip lines up with
  the take's video and sound;
- a tracking-loss frame (all values missing) is dropped: importers interpolate linearly
  from the last tracked pose to the next one across the gap (a gap at the start holds the
  first tracked pose, one at the end the last; glTF holds the end keys outside the clip);
- a frame whose time does not advance past every earlier kept frame (a repeated or
  backwards timestamp) is dropped, as glTF needs strictly increasing times;
- a single missing value in a tracked frame holds that channel's previous value (its
  next one before the first); a channel the take lacks, or never gives, stays at 0.
Weights are written as they are (no clamping); other channels are not animated.

Timing: glTF keys are in seconds and it has no frame rate; Blender places them at its
scene's rate (24 fps, frames 1-250, unless set before the import). The take's rate and
frame range go in the scene's and the animation's ``extras`` (``clip_timing``: fps,
frame_start, frame_end), which Blender imports as the scene's custom properties;
docs/FORMATS.md gives the steps and a script that sets them.

Head: a take with head angles (``meta["pose"]``: HeadYaw, HeadPitch, HeadRoll) gets a node
``head`` above ``face``, at the neck pivot ``PIVOT`` (``face`` carries the opposite
offset, so the face rests where it was), whose ``rotation`` is animated by a second
``LINEAR`` sampler on the same keyframe times: the angles as glTF quaternions
(faceclean.pose: Unity's frame with X mirrored), a missing angle held as the weights
are, consecutive quaternions kept in one hemisphere so that importers interpolate the
short way. The eyes stay what the eyeLook* morph targets show (the face is one mesh).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from faceclean.animation import MAX_ABS, Animation
from faceclean.channels import ARKIT52, pose_name
from faceclean.errors import FacecleanError
from faceclean.face.mesh import FaceMesh
from faceclean.io.gltf_container import data_uri, glb
from faceclean.timing import nominal_rate

_FLOAT, _UINT = 5126, 5125  # glTF componentType
_ARRAY, _ELEMENTS = 34962, 34963  # bufferView targets
PIVOT = (0.0, -0.08, -0.03)  # m, the head node's place: the top of the neck, behind the jaw
HEAD = ("HeadYaw", "HeadPitch", "HeadRoll")
MAX_SPAN = 1e7  # s (116 days) from the first frame: float32 keeps 1 s steps to 1.7e7 s
RATES = (1.0, 1000.0)  # Hz, the frame rates the file names (Blender's FPS is a whole 1 or more)


def keyframes(anim: Animation) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """(times (K,) float32 s from 0, weights (K, 52) float32, counts) by the module's rule.

    ``counts``: ``lost`` tracking-loss frames and ``unordered`` non-advancing frames
    dropped, ``channels`` ARKit channels the take gives.
    """
    values, present = anim.arkit()  # (N, 52), NaN rows where tracking was lost
    if not present.any():
        raise FacecleanError(
            "none of the take's channels is an ARKit blendshape (nothing to animate): "
            f"{', '.join(anim.names[:5])}{', ...' if anim.n_channels > 5 else ''}"
        )
    rows = kept(anim)
    times = (anim.times - anim.times[0]).astype(np.float32)
    valid = anim.valid
    advance = np.isin(np.flatnonzero(valid), rows)
    with np.errstate(invalid="ignore"):  # inf or past any weight (1e308 is inf in float32):
        w = np.where(np.abs(values[rows]) <= MAX_ABS, values[rows], np.nan)  # a missing cell
    weights = _hold(w)  # held from its channel's last, as a tracking loss is
    counts = {
        "lost": int((~valid).sum()),
        "unordered": int((~advance).sum()),
        "channels": int(present.sum()),
    }
    return times[rows], weights.astype(np.float32), counts


def kept(anim: Animation) -> np.ndarray:
    """(K,) indices of the frames that become keyframes (the module's rule)."""
    valid = np.flatnonzero(anim.valid)
    if len(valid) == 0:
        raise FacecleanError("every frame of the take is a tracking loss: no keyframe to write")
    span = float(np.nanmax(np.abs(anim.times[valid] - anim.times[0])))
    if not span <= MAX_SPAN:  # NaN too
        raise FacecleanError(
            f"the take's times span {span:.3g} s: glTF keyframe times (float32 s) hold at "
            f"most {MAX_SPAN:.0e} s (are the times in another unit?)"
        )
    tv = (anim.times - anim.times[0]).astype(np.float32)[valid]
    before = np.maximum.accumulate(np.concatenate([[-np.inf], tv[:-1]]))
    return valid[tv > before]  # strictly later than every earlier tracked frame


def head_rotations(anim: Animation) -> np.ndarray | None:
    """(K,) x 4 glTF quaternions (x, y, z, w) of the head at the keyframes, or None when
    the take has no head angles."""
    from faceclean.pose import gltf_quaternion

    pose = anim.meta.get("pose")
    names = [pose_name(str(n)) for n in anim.meta.get("pose_names", ())]
    if pose is None or not set(HEAD) <= set(names) or np.shape(pose)[0] != anim.n_frames:
        return None
    ypr = np.asarray(pose, np.float64)[kept(anim)][:, [names.index(n) for n in HEAD]]
    q = gltf_quaternion(_hold(ypr))  # (K, 4)
    flip = np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=1) < 0, -1.0, 1.0))
    q[1:] *= flip[:, None]  # each key in the hemisphere of the one before
    return q.astype(np.float32)


def _hold(w: np.ndarray) -> np.ndarray:
    """(K, 52) with each NaN replaced by its channel's previous value, else its next, else 0."""
    w = _forward_fill(w)
    w = _forward_fill(w[::-1])[::-1]
    return np.nan_to_num(w, nan=0.0)


def _forward_fill(w: np.ndarray) -> np.ndarray:
    """(K, M): each NaN takes the last non-NaN value above it in its column (if any)."""
    rows = np.where(np.isnan(w), 0, np.arange(len(w))[:, None])
    return np.take_along_axis(w, np.maximum.accumulate(rows, axis=0), axis=0)


class _Blob:
    """The binary buffer and its views/accessors, built up in order."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []

    def add(self, a: np.ndarray, kind: str, ctype: int, target: int | None, minmax: bool) -> int:
        self.data.extend(b"\0" * (-len(self.data) % 4))
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.data), "byteLength": a.nbytes}
        if target is not None:
            view["target"] = target
        self.data.extend(a.tobytes())
        self.views.append(view)
        acc: dict[str, Any] = {
            "bufferView": len(self.views) - 1,
            "componentType": ctype,
            "count": len(a),
            "type": kind,
        }
        if minmax:
            lo, hi = a.min(0), a.max(0)
            acc["min"], acc["max"] = np.atleast_1d(lo).tolist(), np.atleast_1d(hi).tolist()
        self.accessors.append(acc)
        return len(self.accessors) - 1


def clip_timing(anim: Animation, times: np.ndarray) -> dict[str, float | int]:
    """What glTF has no field for: the take's frame rate (fps: its median, as the named rate
    it is within 0.25 % of, timing.nominal_rate) and
    the clip's frames at that rate, 0 .. frame_end = round(last key time x fps); {} when
    the take has no rate in RATES (one frame; a step of hours or of microseconds).
    Importers that count in frames (Blender) read the key times (s) at the scene's rate,
    so these say which rate and range to set."""
    rate = anim.rate
    if not RATES[0] <= rate <= RATES[1]:  # NaN, 0 (one frame) and absurd rates too
        return {}
    fps = nominal_rate(rate)
    return {"fps": fps, "frame_start": 0, "frame_end": int(round(float(times[-1]) * fps))}


def document(mesh: FaceMesh, anim: Animation | None = None, name: str = "take"):
    """(glTF JSON dict, binary buffer bytes, keyframe counts or None) for ``mesh``, animated
    by ``anim`` when given."""
    from faceclean.face.mesh import normals

    blob = _Blob()
    v = np.ascontiguousarray(mesh.vertices, "<f4")
    attrs = {
        "POSITION": blob.add(v, "VEC3", _FLOAT, _ARRAY, True),
        "NORMAL": blob.add(normals(v, mesh.faces).astype("<f4"), "VEC3", _FLOAT, _ARRAY, False),
    }
    if mesh.colors is not None:
        colors = np.ascontiguousarray(mesh.colors, "<f4")
        attrs["COLOR_0"] = blob.add(colors, "VEC3", _FLOAT, _ARRAY, False)
    indices = np.ascontiguousarray(mesh.faces.reshape(-1), "<u4")
    index_acc = blob.add(indices, "SCALAR", _UINT, _ELEMENTS, False)
    targets = [
        {"POSITION": blob.add(np.ascontiguousarray(d, "<f4"), "VEC3", _FLOAT, _ARRAY, True)}
        for d in mesh.deltas  # (52, V, 3) m
    ]
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "faceclean"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "face"}],
        "meshes": [
            {
                "name": mesh.name,
                "primitives": [
                    {"attributes": attrs, "indices": index_acc, "material": 0, "targets": targets}
                ],
                "weights": [0.0] * len(ARKIT52),
                "extras": {"targetNames": list(ARKIT52), "landmarks": mesh.landmarks},
            }
        ],
        "materials": [
            {
                "name": "skin",
                "pbrMetallicRoughness": {
                    "baseColorFactor": [1, 1, 1, 1],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.75,
                },
                "doubleSided": True,
            }
        ],
    }
    counts = None
    if anim is not None:
        times, weights, counts = keyframes(anim)
        t_acc = blob.add(times.astype("<f4"), "SCALAR", _FLOAT, None, True)
        w_acc = blob.add(weights.reshape(-1).astype("<f4"), "SCALAR", _FLOAT, None, False)
        samplers = [{"input": t_acc, "output": w_acc, "interpolation": "LINEAR"}]
        channels = [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]
        q = head_rotations(anim)
        if q is not None:  # a head node above the face, turning at the neck
            q_acc = blob.add(np.ascontiguousarray(q, "<f4"), "VEC4", _FLOAT, None, False)
            samplers.append({"input": t_acc, "output": q_acc, "interpolation": "LINEAR"})
            channels.append({"sampler": 1, "target": {"node": 1, "path": "rotation"}})
            doc["nodes"][0]["translation"] = [-v for v in PIVOT]
            doc["nodes"].append({"name": "head", "children": [0], "translation": list(PIVOT)})
            doc["scenes"] = [{"nodes": [1]}]
        timing = clip_timing(anim, times)
        counts.update(timing, seconds=float(times[-1]))  # the clip's length
        if timing:
            doc["scenes"][0]["extras"] = timing  # Blender: the scene's custom properties
        doc["animations"] = [
            {
                "name": name,
                "samplers": samplers,
                "channels": channels,
                "extras": {"droppedTrackingLoss": counts["lost"], **timing},
            }
        ]
    doc["accessors"], doc["bufferViews"] = blob.accessors, blob.views
    doc["buffers"] = [{"byteLength": len(blob.data)}]
    return doc, bytes(blob.data), counts


def encode(doc: dict[str, Any], data: bytes, binary: bool) -> bytes:
    """GLB bytes (JSON and BIN chunks), or .gltf JSON with the buffer as a data URI."""
    doc = dict(doc, buffers=[dict(doc["buffers"][0])])
    if binary:
        return glb(doc, data)
    doc["buffers"][0]["uri"] = data_uri(data)
    return (json.dumps(doc, indent=1) + "\n").encode("utf-8")


def write(
    anim: Animation,
    f: BinaryIO,
    path: str | os.PathLike | None = None,
    mesh: FaceMesh | None = None,
    name: str | None = None,
) -> dict[str, float]:
    """Write ``anim`` on ``mesh`` (the stylised face by default); GLB unless ``path`` ends
    in ``.gltf``. Returns the keyframe counts (see :func:`keyframes`) and the clip's
    timing (:func:`clip_timing`)."""
    if mesh is None:
        from faceclean.face.mesh import stylised

        mesh = stylised()
    p = Path(path) if path is not None else None
    label = name or (p.stem if p is not None else "take")
    doc, data, counts = document(mesh, anim, label)
    f.write(encode(doc, data, binary=p is None or p.suffix.lower() != ".gltf"))
    return counts


def save_mesh(mesh: FaceMesh, path: str | os.PathLike) -> None:
    """The mesh alone as a GLB file, atomically: positions, normals, colours, indices and
    52 dense morph targets named in ``mesh.extras.targetNames`` (weights 0), no animation
    (``faceclean face-mesh``)."""
    from faceclean.io.atomic import atomic_write

    doc, data, _ = document(mesh)
    atomic_write(path, glb(doc, data))
