"""The report's data as compact JSON: curves, face weights and the face mesh.

Weights are integers ``round(value * SCALE)`` (3 decimals; null where missing), times are
seconds from the first frame rounded to 0.1 ms, and long clips keep every k-th frame so
that the page stays small (at most ``MAX_VALUES`` numbers over all series). The mesh is
base64 binary: float32 positions, uint32 triangles, uint8 colours, and per ARKit channel
the vertices its target moves with int16 deltas times a per-target scale ``q``. A version
with head angles (``meta["pose"]``: HeadYaw, HeadPitch, HeadRoll) carries ``head``: three
lists (yaw, pitch, roll) in radians, 4 decimals, at the kept frames; the viewer turns its
face by them (the glTF convention of faceclean.pose).
"""

from __future__ import annotations

import base64
import math
from typing import Any

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import GROUPS, INDEX, channel_key, pose_name
from faceclean.evaluation.comparison import Comparison, change
from faceclean.face.mesh import FaceMesh

SCALE = 1000  # stored weight units per unit weight
MAX_VALUES = 1_600_000  # numbers in all series together, past which frames are decimated
MIN_FRAMES = 600  # never decimate below this many frames
MOVE = 1e-4  # a target moves a vertex when |delta| > MOVE x the mesh's bounding diagonal
OPEN_PER_GROUP = 4  # channels shown per group before "more"
TITLES = {"eyes": "eyes", "brows": "brows", "jaw": "jaw", "mouth": "mouth"}
TITLES["cheeks_nose"] = "cheeks and nose"


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def stride(n_frames: int, n_values_per_frame: int) -> int:
    """Keep every k-th frame: the smallest k that fits MAX_VALUES (1 for short clips)."""
    cap = max(MIN_FRAMES, MAX_VALUES // max(n_values_per_frame, 1))
    return max(1, math.ceil(n_frames / cap))


def _ints(values: np.ndarray) -> list[list[int | None]]:
    """(N, M) weights -> M lists of ints (None for NaN)."""
    q = np.round(values * SCALE)
    ok = np.isfinite(q)
    q = np.where(ok, q, 0).astype(np.int64)
    return [
        [int(v) if good else None for v, good in zip(q[:, j], ok[:, j], strict=True)]
        for j in range(values.shape[1])
    ]


HEAD = ("HeadYaw", "HeadPitch", "HeadRoll")


def head(anim: Animation | None, keep: np.ndarray) -> list[list[float | None]] | None:
    """(yaw, pitch, roll) lists in rad at frames ``keep`` (None where missing), or None
    when ``anim`` has no head angles."""
    pose = None if anim is None else anim.meta.get("pose")
    names = [pose_name(str(n)) for n in (anim.meta.get("pose_names", ()) if anim else ())]
    if pose is None or not set(HEAD) <= set(names) or len(pose) != anim.n_frames:
        return None
    ypr = np.asarray(pose, np.float64)[keep][:, [names.index(n) for n in HEAD]]
    return [[round(float(v), 4) if np.isfinite(v) else None for v in col] for col in ypr.T]


def animation(comp: Comparison) -> dict[str, Any]:
    """Curves and face weights of every version in ``comp`` (see the module docstring)."""
    versions = [("input", "input", comp.input.values, comp.input)]
    if comp.truth is not None:
        versions.append(("truth", "truth", comp.truth.values, comp.truth))
    versions += [(label, "output", out.values, out) for label, out in comp.outputs.items()]
    m = comp.input.n_channels
    k = stride(comp.input.n_frames, m * len(versions))
    keep = np.arange(0, comp.input.n_frames, k)
    if keep[-1] != comp.input.n_frames - 1:
        keep = np.append(keep, comp.input.n_frames - 1)
    names = [channel_key(n) for n in comp.input.names]
    moved = change(comp.input.values, comp.outputs[comp.main].values)
    moved = np.nan_to_num(moved)
    groups = []
    for g, members in GROUPS.items():
        cols = [j for j, n in enumerate(names) if n in members]
        if cols:
            cols.sort(key=lambda j: -moved[j])
            groups.append({"title": TITLES.get(g, g), "channels": cols})
    other = [j for j, n in enumerate(names) if n not in INDEX]
    if other:
        groups.append({"title": "other", "channels": sorted(other, key=lambda j: -moved[j])})
    times = comp.times[keep]
    ok = np.isfinite(times)
    if not ok.all():  # a frame without a timestamp sits between its neighbours
        times = np.interp(np.arange(len(times)), np.flatnonzero(ok), times[ok])
    times = np.maximum.accumulate(times)  # the player needs non-decreasing time
    return {
        "times": [round(float(t), 4) for t in times],
        "scale": SCALE,
        "stride": k,
        "channels": names,
        "arkit": [INDEX.get(n, -1) for n in names],
        "change": [round(float(x), 4) for x in moved],
        "series": [
            {"label": label, "kind": kind, "values": _ints(values[keep]), "head": head(a, keep)}
            for label, kind, values, a in versions
        ],
        "face": [0, 2 if comp.truth is not None else 1],
        "groups": groups,
        "open_per_group": OPEN_PER_GROUP,
    }


def mesh(face: FaceMesh) -> dict[str, Any]:
    """The face mesh with sparse, int16-quantised targets (see the module docstring)."""
    v = np.asarray(face.vertices, np.float32)
    diagonal = float(np.linalg.norm(v.max(0) - v.min(0))) or 1.0
    targets, index, delta = [], [], []
    for j in range(len(face.deltas)):
        d = np.asarray(face.deltas[j], np.float64)
        rows = np.flatnonzero(np.abs(d).max(1) > MOVE * diagonal)
        if len(rows) == 0:
            continue
        q = float(np.abs(d[rows]).max()) / 32767.0
        targets.append({"ch": j, "n": int(len(rows)), "q": q})
        index.append(rows.astype("<u4"))
        delta.append(np.round(d[rows] / q).astype("<i2"))
    colors = None
    if face.colors is not None:
        colors = _b64(np.round(np.clip(face.colors, 0, 1) * 255).astype(np.uint8))
    return {
        "name": face.name,
        "positions": _b64(v.astype("<f4")),
        "indices": _b64(np.asarray(face.faces, "<u4")),
        "colors": colors,
        "targets": targets,
        "target_index": _b64(np.concatenate(index) if index else np.zeros(0, "<u4")),
        "target_delta": _b64(np.concatenate(delta) if delta else np.zeros((0, 3), "<i2")),
    }
