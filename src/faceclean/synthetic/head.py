"""The ICT head to render: geometry by identity and ARKit weights, and its painted regions.

``Head.load(path)`` reads ``ict_full.npz`` (its README in ``../shared/data/meshes``):
vertices ``v = neutral + alpha . identity_modes + w . arkit_deltas`` in cm, x to the
subject's left, y up, z out of the face. The four thin transparent layers (lacrimal fluid,
eye blend, eye occlusion, lashes) are left out. The model has no textures, so the regions a
tracker looks at are painted per vertex from the 68 Multi-PIE landmarks: lips (inside the
outer-lip contour), brows (near the brow polylines), a dark lid margin where lashes would
be, and the iris and pupil (the front cap of each eyeball).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.io.npz_safe import load_arrays

MATERIALS = ("M_Face", "M_BackHead", "M_GumsTongue", "M_Teeth")
EYES = ("M_ScleraLeft", "M_ScleraRight")  # the iris meshes sit inside the sclera's cornea
KEYS = (
    "neutral_vertices",
    "triangles",
    "triangle_material",
    "material_names",
    "arkit_names",
    "arkit_deltas",
    "identity_modes",
    "landmark_vertices",
)
GEOMETRY = ("neutral_vertices", "arkit_deltas", "identity_modes")  # cm, summed per vertex
MAX_CM = 1000.0  # |coordinate| of any of them: a head is ~20 cm, a bound keeps sums finite
# region codes of Head.region (one per vertex): what paint a vertex gets
SKIN, BACK, MOUTH, TEETH, SCLERA, IRIS, PUPIL, LIPS, BROW, LID = range(10)


@dataclass(eq=False)
class Head:
    neutral: np.ndarray  # (V, 3) float32 cm, only the rendered vertices
    deltas: np.ndarray  # (52, V*3) float32, canonical ARKit order (tongueOut may be zero)
    modes: np.ndarray  # (K, V*3) float32 identity modes
    triangles: np.ndarray  # (T, 3) int32 into the rendered vertices
    region: np.ndarray  # (V,) int8 paint code
    normal_sum: sparse.csr_matrix  # (V, T): vertex normal = sum of its triangles' normals
    pivot: np.ndarray  # (3,) cm, the point the head turns about (between the ears)
    landmarks: np.ndarray  # (68,) int, Multi-PIE landmark vertices (into the rendered ones)
    eye_angle: np.ndarray  # (V,) deg from the eyeball's front axis; NaN off the eyeballs
    brow_cm: np.ndarray  # (V,) cm to the nearest brow polyline (inf off the front skin)
    lid_cm: np.ndarray  # (V,) cm to the nearest lid contour (inf off the front skin)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Head:
        z = load_arrays(path, max_bytes=512 << 20, what="head mesh (ict_full.npz)")
        missing = [k for k in KEYS if k not in z]
        if missing:
            raise FacecleanError(f"{os.fspath(path)}: not an ICT head mesh (no {missing[0]!r})")
        try:
            _check_geometry(z, os.fspath(path))
            return _build(z)
        except (ValueError, IndexError, TypeError) as e:
            raise FacecleanError(f"{os.fspath(path)}: malformed head mesh ({e})") from None

    @property
    def n_identity(self) -> int:
        return self.modes.shape[0]

    def identity(self, alpha: np.ndarray) -> np.ndarray:
        """(V*3,) neutral shape of the identity ``alpha`` (K,) (ICT's sampler: alpha ~ N(0, 1))."""
        return self.neutral.reshape(-1) + alpha.astype(np.float32) @ self.modes

    def vertices(self, base: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """(V, 3) cm for an identity's ``base`` (V*3,) and ARKit ``weights`` (52,)."""
        return (base + weights.astype(np.float32) @ self.deltas).reshape(-1, 3)

    def regions(self, iris_deg: float = 21.0, pupil_deg: float = 8.0, brow_cm: float = 0.45,
                lid_cm: float = 0.18) -> np.ndarray:  # fmt: skip
        """(V,) paint codes for one look: an iris of ``iris_deg`` half-angle round a pupil of
        ``pupil_deg``, brows ``brow_cm`` either side of their line, lid margins (lashes)
        ``lid_cm`` wide; ``region`` is the default look."""
        out = self.region.copy()
        eye = ~np.isnan(self.eye_angle)
        out[eye] = SCLERA
        out[eye & (self.eye_angle < iris_deg)] = IRIS
        out[eye & (self.eye_angle < pupil_deg)] = PUPIL
        paintable = np.isin(self.region, (SKIN, BROW, LID))
        out[paintable] = SKIN
        out[paintable & (self.brow_cm < brow_cm)] = BROW
        out[paintable & (self.lid_cm < lid_cm) & (out == SKIN)] = LID
        return out

    def normals(self, v: np.ndarray) -> np.ndarray:
        """(V, 3) unit area-weighted vertex normals."""
        a, b, c = (v[self.triangles[:, k]] for k in range(3))
        n = self.normal_sum @ np.cross(b - a, c - a)
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)


def _check_geometry(z: dict[str, np.ndarray], label: str) -> None:
    """Refuse vertices, deltas or modes that are not finite cm within +-MAX_CM (a NaN
    vertex would be rendered as a broken face, not said)."""
    for k in GEOMETRY:
        a = z[k]
        if a.dtype.kind not in "fiu":
            raise FacecleanError(f"{label}: malformed head mesh ({k!r} is {a.dtype}, not numbers)")
        if not np.isfinite(a).all():
            raise FacecleanError(f"{label}: {k!r} holds NaN or infinite values (a broken export)")
        top = float(np.abs(a).max()) if a.size else 0.0
        if top > MAX_CM:
            raise FacecleanError(f"{label}: {k!r} reaches {top:.3g} cm (a head is within 10 m)")


def _build(z: dict[str, np.ndarray]) -> Head:
    names = [str(n) for n in z["material_names"]]
    keep_mat = [names.index(m) for m in MATERIALS + EYES]
    tri_all = z["triangles"].astype(np.int64)
    mat = z["triangle_material"].astype(np.int64)
    keep = np.isin(mat, keep_mat)
    used = np.unique(tri_all[keep])
    remap = np.full(len(z["neutral_vertices"]), -1, np.int64)
    remap[used] = np.arange(len(used))
    tris = remap[tri_all[keep]].astype(np.int32)
    tri_mat = mat[keep]
    v0 = z["neutral_vertices"].astype(np.float32)[used]
    cmap = ChannelMap(ARKIT52, [str(n) for n in z["arkit_names"]])
    deltas = np.zeros((52, len(used), 3), np.float32)
    deltas[cmap.have] = z["arkit_deltas"][cmap.cols][:, used].astype(np.float32)
    modes = z["identity_modes"][:, used].astype(np.float32)

    region = np.full(len(used), SKIN, np.int8)
    for code, m in ((BACK, "M_BackHead"), (MOUTH, "M_GumsTongue"), (TEETH, "M_Teeth")):
        region[np.unique(tris[tri_mat == names.index(m)])] = code
    eye_angle = np.full(len(used), np.nan, np.float32)
    for sclera in EYES:
        # the eyeball's front cap is the iris (21 deg half-angle) and its centre the pupil
        sv = np.unique(tris[tri_mat == names.index(sclera)])
        centre = (v0[sv].min(0) + v0[sv].max(0)) / 2
        d = v0[sv] - centre
        angle = np.degrees(np.arccos(np.clip(d[:, 2] / np.linalg.norm(d, axis=1), -1, 1)))
        eye_angle[sv] = angle
        region[sv] = SCLERA
        region[sv[angle < 21.0]] = IRIS
        region[sv[angle < 8.0]] = PUPIL
    lm = remap[z["landmark_vertices"].astype(np.int64)]
    face = region == SKIN
    brow_cm, lid_cm = _paint_regions(v0, lm, face, region)

    n_t = len(tris)
    rows = tris.reshape(-1)
    cols = np.repeat(np.arange(n_t), 3)
    normal_sum = sparse.csr_matrix(
        (np.ones(3 * n_t, np.float32), (rows, cols)), shape=(len(used), n_t)
    )
    # pivot: behind the face, level with the eyes (a neck-and-skull turn, not the nose)
    pivot = np.array([0.0, v0[lm[[36, 45]], 1].mean() - 4.0, v0[:, 2].min() + 3.0], np.float32)
    return Head(
        neutral=v0,
        deltas=deltas.reshape(52, -1),
        modes=modes.reshape(len(modes), -1),
        triangles=tris,
        region=region,
        normal_sum=normal_sum,
        pivot=pivot,
        landmarks=lm,
        eye_angle=eye_angle,
        brow_cm=brow_cm,
        lid_cm=lid_cm,
    )


def _paint_regions(v0: np.ndarray, lm: np.ndarray, face: np.ndarray, region: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Lips, brows and lid margins from the 68 landmarks, on the frontal (x, y) projection;
    returns each vertex's distance (cm) to the brows and to the lids (inf off the front
    skin), from which ``Head.regions`` paints other looks."""
    from matplotlib.path import Path as Polygon  # a point-in-polygon test

    front = face & (v0[:, 2] > v0[lm[[36, 45, 48, 54]], 2].min() - 1.0)
    xy = v0[:, :2]
    lips = Polygon(v0[lm[48:60], :2]).contains_points(xy)
    mouth_gap = Polygon(v0[lm[60:68], :2]).contains_points(xy)
    region[front & lips & ~mouth_gap] = LIPS
    brow_cm = np.full(len(v0), np.inf, np.float32)
    lid_cm = np.full(len(v0), np.inf, np.float32)
    skin = front & (region == SKIN)
    for brow in (lm[17:22], lm[22:27]):
        d = _polyline_distance(xy, v0[brow, :2])
        brow_cm[skin] = np.minimum(brow_cm[skin], d[skin])
        region[front & (d < 0.45) & (region == SKIN)] = BROW
    for eye in (lm[36:42], lm[42:48]):
        loop = np.concatenate([eye, eye[:1]])
        d = _polyline_distance(xy, v0[loop, :2])
        lid_cm[skin] = np.minimum(lid_cm[skin], d[skin])
        region[front & (d < 0.18) & (region == SKIN)] = LID
    return brow_cm, lid_cm


def _polyline_distance(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    """(N,) distance of points p (N, 2) to the polyline ``line`` (K, 2)."""
    best = np.full(len(p), np.inf)
    for a, b in zip(line[:-1], line[1:], strict=True):
        ab = b - a
        u = np.clip(((p - a) @ ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (a + u[:, None] * ab), axis=1))
    return best
