"""Face meshes with ARKit blendshapes, and the 6 vertex pairs of the distance loss.

A face is its neutral vertices (V, 3), one delta per ARKit channel (52, V, 3) in
canonical order (zeros where the mesh lacks the shape) and 6 vertex pairs whose
distances the loss compares (SPEC section 2). Vertices for weights w (..., 52):
``v = neutral + w @ deltas``.

The pairs are picked by a rule that needs only the shapes, never vertex numbers:

- lip opening at 1/3, 1/2 and 2/3 of the way from the right to the left mouth corner:
  of the vertex pairs closer than 3 % of the mesh's bounding-box diagonal in the neutral
  face, with both vertices within 1/48 of the mouth width of that fraction (1/24, then
  1/12, on coarse meshes), keep those that ``jawOpen`` = 1 pulls apart at least half as
  much as the best; take the closest in the neutral face (where the lips meet);
- mouth corners: the vertex ``mouthSmileRight`` moves most, and ``mouthSmileLeft``'s;
- eyelid opening, per side: the upper-lid vertex ``eyeBlink*`` moves most, and the
  lower-lid vertex (one that blink moves less than half as much) nearest to where the
  upper lid lands when the eye is closed.

Distances are reported in mouth widths (the neutral corner-to-corner distance), so a
mesh in metres and one in centimetres give the same numbers.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from faceclean.channels import ARKIT52, INDEX, canonical
from faceclean.errors import FacecleanError
from faceclean.settings import data_dir

PAIR_NAMES = (
    "lip_right_third",
    "lip_middle",
    "lip_left_third",
    "mouth_corners",
    "eyelid_left",
    "eyelid_right",
)
NEIGHBOUR = 0.03  # lip pairs: neutral distance below this share of the mesh diagonal
BANDS = (1 / 48, 1 / 24, 1 / 12)  # lip pairs: +- share of the mouth width around 1/3, 1/2, 2/3


@dataclass(frozen=True)
class Face:
    """A face mesh, its ARKit deltas, and the 6 loss pairs (see the module docstring)."""

    neutral: np.ndarray  # (V, 3) mesh units
    deltas: np.ndarray  # (52, V, 3) mesh units per unit weight
    pairs: np.ndarray  # (6, 2) vertex indices, in PAIR_NAMES order
    scale: float  # mesh units per mouth width

    def distances(self, weights: np.ndarray) -> np.ndarray:
        """(..., 6) pair distances in mouth widths for weights (..., 52)."""
        w = np.asarray(weights, dtype=np.float64)
        v0 = self.neutral[self.pairs]  # (6, 2, 3)
        dv = self.deltas[:, self.pairs]  # (52, 6, 2, 3)
        p = v0 + np.tensordot(w, dv, axes=(-1, 0))  # (..., 6, 2, 3)
        return np.linalg.norm(p[..., 0, :] - p[..., 1, :], axis=-1) / self.scale


def default_mesh() -> Path:
    """The ARKit reference mesh in the shared data folder."""
    d = data_dir()
    path = d / "meshes" / "arkit_reference_mesh.npz" if d is not None else None
    if path is None or not path.is_file():
        raise FacecleanError("no face mesh: the shared data folder lacks meshes/ (give --mesh)")
    return path


def load_face(path: str | os.PathLike | None = None, pairs: np.ndarray | None = None) -> Face:
    """A :class:`Face` from an npz or GLB mesh (default: the ARKit reference mesh).

    ``pairs`` (6, 2) vertex indices replace the rule's choice.
    """
    p = Path(path) if path is not None else default_mesh()
    if not p.is_file():
        raise FacecleanError(f"no such mesh file: {p}")
    if p.suffix.lower() == ".npz":
        neutral, deltas = _read_npz(p)
    elif p.suffix.lower() in (".glb", ".gltf"):
        neutral, deltas = _read_gltf(p)
    else:
        raise FacecleanError(f"{p.name}: a face mesh must be .npz or .glb")
    for name in ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight", "mouthSmileLeft", "mouthSmileRight"):
        if not np.any(deltas[INDEX[name]]):
            raise FacecleanError(f"{p.name}: the mesh has no {name} shape")
    if pairs is None:
        pairs = select_pairs(neutral, deltas)
    pairs = np.asarray(pairs, dtype=np.int64)
    if pairs.shape != (6, 2) or pairs.min() < 0 or pairs.max() >= len(neutral):
        raise FacecleanError(f"vertex pairs must be 6 pairs of indices below {len(neutral)}")
    corners = pairs[PAIR_NAMES.index("mouth_corners")]
    scale = float(np.linalg.norm(neutral[corners[0]] - neutral[corners[1]]))
    if not scale > 0:
        raise FacecleanError("the mouth corners coincide: give other vertex pairs")
    return Face(neutral, deltas, pairs, scale)


def select_pairs(neutral: np.ndarray, deltas: np.ndarray) -> np.ndarray:
    """(6, 2) vertex pairs by the rule of the module docstring."""

    def most_moved(name: str) -> int:
        return int(np.argmax(np.linalg.norm(deltas[INDEX[name]], axis=1)))

    right, left = most_moved("mouthSmileRight"), most_moved("mouthSmileLeft")
    axis = neutral[left] - neutral[right]
    width2 = float(axis @ axis)
    if width2 <= 0:
        raise FacecleanError("mesh: the mouth corners coincide")
    diagonal = float(np.linalg.norm(neutral.max(0) - neutral.min(0)))
    near = np.array(sorted(cKDTree(neutral).query_pairs(NEIGHBOUR * diagonal)), dtype=np.int64)
    if len(near) == 0:
        raise FacecleanError("mesh: no vertex pairs near each other")
    jaw = deltas[INDEX["jawOpen"]]
    a, b = near[:, 0], near[:, 1]
    rest = np.linalg.norm(neutral[a] - neutral[b], axis=1)  # (P,) neutral distance
    gain = np.linalg.norm(neutral[a] + jaw[a] - neutral[b] - jaw[b], axis=1) - rest
    s = (neutral - neutral[right]) @ axis / width2  # (V,) 0 right corner .. 1 left corner
    lips = []
    for f in (1 / 3, 1 / 2, 2 / 3):
        for band in BANDS:  # the narrowest band the mesh's resolution allows
            inside = (np.abs(s[a] - f) <= band) & (np.abs(s[b] - f) <= band) & (gain > 0)
            if inside.any():
                break
        else:
            raise FacecleanError(f"mesh: no lip vertices at {f:.2f} of the mouth width")
        k = np.flatnonzero(inside & (gain >= 0.5 * gain[inside].max()))
        k = k[np.argmin(rest[k])]  # the lips meet at the seam: the closest good opener
        lips.append(near[k])
    out = [*lips, np.array([right, left])]
    for side in ("Left", "Right"):
        blink = deltas[INDEX["eyeBlink" + side]]
        moved = np.linalg.norm(blink, axis=1)  # (V,)
        upper = int(np.argmax(moved))
        landed = neutral[upper] + blink[upper]
        still = np.flatnonzero(moved < 0.5 * moved[upper])
        lower = still[np.argmin(np.linalg.norm(neutral[still] + blink[still] - landed, axis=1))]
        out.append(np.array([upper, lower]))
    return np.stack(out)


def _read_npz(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(neutral, deltas) from the reference layout, ICT's ``arkit_*`` view, or any npz
    with ``neutral_vertices`` + ``blendshape_deltas`` + ``names``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            keys = set(z.files)
            neutral = z["neutral_vertices"]
            if {"arkit_deltas", "arkit_names"} <= keys:
                deltas, names = z["arkit_deltas"], z["arkit_names"]
            else:
                deltas, names = z["blendshape_deltas"], z["names"]
    except (KeyError, ValueError, OSError, EOFError) as e:
        raise FacecleanError(f"{path.name}: not a face mesh npz ({e})") from None
    return _canonical(path.name, neutral, deltas, [str(n) for n in names])


def _canonical(
    label: str, neutral: np.ndarray, deltas: np.ndarray, names: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    neutral = np.asarray(neutral, dtype=np.float64)
    deltas = np.asarray(deltas, dtype=np.float64)
    if neutral.ndim != 2 or neutral.shape[1] != 3 or deltas.shape[1:] != neutral.shape:
        raise FacecleanError(f"{label}: vertices {neutral.shape} and deltas {deltas.shape}")
    if len(names) != len(deltas):
        raise FacecleanError(f"{label}: {len(names)} names for {len(deltas)} shapes")
    out = np.zeros((len(ARKIT52), *neutral.shape))
    for j, n in enumerate(names):
        c = canonical(n)
        if c is not None:
            out[INDEX[c]] = deltas[j]
    if not (np.all(np.isfinite(neutral)) and np.all(np.isfinite(out))):
        raise FacecleanError(f"{label}: non-finite vertex positions")
    return neutral, out


def _read_gltf(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(neutral, deltas) of the first mesh with ARKit-named morph targets in a GLB/glTF."""
    import pygltflib

    try:
        gltf = pygltflib.GLTF2().load(str(path))
    except Exception as e:  # pygltflib raises many kinds on a bad file
        raise FacecleanError(f"{path.name}: not a readable glTF file ({e})") from None
    for mesh in gltf.meshes or []:
        names = (mesh.extras or {}).get("targetNames") if isinstance(mesh.extras, dict) else None
        prim = mesh.primitives[0] if mesh.primitives else None
        if not names or prim is None or not prim.targets:
            continue
        neutral = _accessor(gltf, prim.attributes.POSITION)
        deltas = np.stack([_accessor(gltf, t["POSITION"]) for t in prim.targets])
        return _canonical(path.name, neutral, deltas, [str(n) for n in names])
    raise FacecleanError(f"{path.name}: no mesh with named morph targets (extras.targetNames)")


def _accessor(gltf, index: int) -> np.ndarray:
    """(count, 3) float vertices of a VEC3 FLOAT accessor (dense)."""
    acc = gltf.accessors[index]
    if acc.type != "VEC3" or acc.componentType != 5126 or acc.bufferView is None:
        raise FacecleanError("mesh: only dense float VEC3 positions are supported")
    view = gltf.bufferViews[acc.bufferView]
    data = gltf.binary_blob() if gltf.buffers[view.buffer].uri is None else None
    if data is None:
        data = gltf.get_data_from_buffer_uri(gltf.buffers[view.buffer].uri)
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    stride = view.byteStride or 12
    raw = np.frombuffer(data, dtype=np.uint8, count=stride * (acc.count - 1) + 12, offset=start)
    rows = np.lib.stride_tricks.as_strided(raw, (acc.count, 12), (stride, 1))
    return rows.copy().view("<f4").reshape(acc.count, 3).astype(np.float64)
