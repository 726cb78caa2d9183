"""The 6 vertex pairs of the distance loss on a face mesh (SPEC section 2).

A :class:`LossFace` is a :class:`~faceclean.face.mesh.FaceMesh` (any the mesh reader
reads: npz, glTF/GLB, the stylised face) plus 6 vertex pairs whose distances the loss
compares. Vertices for weights w (..., 52): ``v = vertices + w @ deltas``.

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

from faceclean.channels import INDEX
from faceclean.errors import FacecleanError
from faceclean.face.mesh import FaceMesh, load
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
NEEDS = ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight", "mouthSmileLeft", "mouthSmileRight")


@dataclass(frozen=True, eq=False)
class LossFace:
    """A face mesh and the 6 loss pairs (see the module docstring)."""

    mesh: FaceMesh
    pairs: np.ndarray  # (6, 2) vertex indices, in PAIR_NAMES order
    scale: float  # mesh units per mouth width

    def distances(self, weights: np.ndarray) -> np.ndarray:
        """(..., 6) pair distances in mouth widths for weights (..., 52)."""
        w = np.asarray(weights, dtype=np.float64)
        v0 = self.mesh.vertices[self.pairs].astype(np.float64)  # (6, 2, 3)
        dv = self.mesh.deltas[:, self.pairs].astype(np.float64)  # (52, 6, 2, 3)
        p = v0 + np.tensordot(w, dv, axes=(-1, 0))  # (..., 6, 2, 3)
        return np.linalg.norm(p[..., 0, :] - p[..., 1, :], axis=-1) / self.scale


def default_mesh() -> Path:
    """The ARKit reference mesh in the shared data folder."""
    d = data_dir()
    path = d / "meshes" / "arkit_reference_mesh.npz" if d is not None else None
    if path is None or not path.is_file():
        raise FacecleanError("no face mesh: the shared data folder lacks meshes/ (give --mesh)")
    return path


def load_face(path: str | os.PathLike | None = None, pairs: np.ndarray | None = None) -> LossFace:
    """A :class:`LossFace` from an npz or glTF/GLB mesh (default: the ARKit reference mesh).

    ``pairs`` (6, 2) vertex indices replace the rule's choice.
    """
    p = Path(path) if path is not None else default_mesh()
    return loss_face(load(p), pairs, p.name)


def loss_face(mesh: FaceMesh, pairs: np.ndarray | None = None, label: str = "mesh") -> LossFace:
    """``mesh`` with the 6 loss pairs: ``pairs`` (6, 2) vertex indices, else the rule's."""
    for name in NEEDS:
        if not np.any(mesh.deltas[INDEX[name]]):
            raise FacecleanError(f"{label}: the mesh has no {name} shape")
    neutral = mesh.vertices.astype(np.float64)
    if pairs is None:
        pairs = select_pairs(neutral, mesh.deltas.astype(np.float64))
    pairs = np.asarray(pairs, dtype=np.int64)
    if pairs.shape != (6, 2) or pairs.min() < 0 or pairs.max() >= len(neutral):
        raise FacecleanError(f"vertex pairs must be 6 pairs of indices below {len(neutral)}")
    corners = pairs[PAIR_NAMES.index("mouth_corners")]
    scale = float(np.linalg.norm(neutral[corners[0]] - neutral[corners[1]]))
    if not scale > 0:
        raise FacecleanError("the mouth corners coincide: give other vertex pairs")
    return LossFace(mesh, pairs, scale)


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
