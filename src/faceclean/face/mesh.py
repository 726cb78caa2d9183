"""The face mesh: the stylised face, a user's mesh (npz or glTF/GLB), GLB export.

A :class:`FaceMesh` is a triangle mesh with one morph target per ARKit channel, in
canonical order (zeros where the mesh lacks a shape), and optional vertex colours.
Vertices for weights w (52,): ``v = vertices + tensordot(w, deltas, 1)``. The one type the
report's viewer, the glTF writer (:mod:`faceclean.io.gltf_take`, which also saves a mesh
alone: ``save_mesh``) and the distance loss (:mod:`faceclean.face.vertex_pairs`) use.

GLB files carry the targets on the first primitive of the first mesh that has them, with
their ARKit names in ``mesh.extras.targetNames`` (the convention Blender and three.js
read); node transforms are ignored (the viewer frames the mesh by its bounding box).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError


@dataclass(eq=False)
class FaceMesh:
    """A face mesh with ARKit morph targets."""

    vertices: np.ndarray  # (V, 3) float32, mesh units (m for ours)
    faces: np.ndarray  # (F, 3) uint32 vertex indices
    deltas: np.ndarray  # (52, V, 3) float32, canonical ARKit order
    colors: np.ndarray | None = None  # (V, 3) float32 linear RGB in [0, 1], or None
    name: str = "face"
    landmarks: dict[str, int] = field(default_factory=dict)  # named vertex indices

    @property
    def present(self) -> np.ndarray:
        """(52,) bool: channels whose target moves at least one vertex."""
        return np.any(self.deltas != 0, axis=(1, 2))

    def pose(self, weights: np.ndarray) -> np.ndarray:
        """(V, 3) vertices for weights (52,)."""
        w = np.asarray(weights, dtype=np.float64).reshape(len(ARKIT52))
        return self.vertices + np.tensordot(w, self.deltas, axes=1)


def stylised() -> FaceMesh:
    """faceclean's own stylised face, 52 targets, coloured (see faceclean.face.parts)."""
    from faceclean.face import parts

    neutral, faces, colors, deltas = parts.build()
    linear = np.asarray(colors, np.float64) ** 2.2  # sRGB-looking palette -> linear (glTF)
    return FaceMesh(
        neutral.astype(np.float32),
        faces.astype(np.uint32),
        deltas.astype(np.float32),
        linear.astype(np.float32),
        "faceclean stylised face",
        parts.landmarks(),
    )


def load(path: str | os.PathLike) -> FaceMesh:
    """A face mesh from an npz (``neutral_vertices``, ``faces``/``triangles``, deltas and
    names as in ../shared/data/meshes) or a GLB/glTF with ARKit-named morph targets."""
    from faceclean.io.source import regular

    p = Path(path)
    regular(p, "mesh file")
    suffix = p.suffix.lower()
    if suffix == ".npz":
        mesh = _read_npz(p)
    elif suffix in (".glb", ".gltf"):
        mesh = _read_gltf(p)
    else:
        raise FacecleanError(f"{p.name}: a face mesh must be .npz, .glb or .gltf")
    if not mesh.present.any():
        raise FacecleanError(f"{p.name}: no morph target has an ARKit name")
    if len(mesh.faces) == 0 or int(mesh.faces.max()) >= len(mesh.vertices):
        raise FacecleanError(f"{p.name}: triangle indices do not match the vertices")
    if not (np.isfinite(mesh.vertices).all() and np.isfinite(mesh.deltas).all()):
        raise FacecleanError(f"{p.name}: non-finite vertex positions")
    return mesh


def _arkit_deltas(label: str, vertices: np.ndarray, deltas, names) -> np.ndarray:
    """(52, V, 3) from targets in any order and spelling (unknown names dropped)."""
    if len(names) != len(deltas):
        raise FacecleanError(f"{label}: {len(names)} target names for {len(deltas)} targets")
    cols = ChannelMap(ARKIT52, [str(n) for n in names])
    out = np.zeros((len(ARKIT52), *vertices.shape), np.float32)
    out[cols.have] = np.asarray(deltas, np.float32)[cols.cols]
    return out


def _read_npz(path: Path) -> FaceMesh:
    from faceclean.io.npz_safe import load_arrays
    from faceclean.io.source import MAX_UNPACKED

    z = load_arrays(path, MAX_UNPACKED, "face mesh npz")  # truncated, foreign: one line
    try:
        vertices = np.asarray(z["neutral_vertices"], np.float32)
        faces = z["faces"] if "faces" in z else z["triangles"]
        if {"arkit_deltas", "arkit_names"} <= set(z):
            deltas, names = z["arkit_deltas"], z["arkit_names"]
        else:
            deltas, names = z["blendshape_deltas"], z["names"]
        deltas = np.asarray(deltas, np.float32)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or deltas.shape[1:] != vertices.shape:
            raise ValueError(f"vertices {vertices.shape}, deltas {deltas.shape}")
        if faces.dtype.kind not in "iu" or names.ndim != 1:
            raise ValueError("faces must be integers and names a list")
        if faces.ndim != 2 or faces.shape[1] != 3:  # quads or pairs read as triangles: scrambled
            raise ValueError(f"faces {faces.shape}: triangles are (F, 3) vertex indices")
        if faces.size and not 0 <= faces.min() <= faces.max() < len(vertices):
            raise ValueError(f"a face's vertex index is outside 0..{len(vertices) - 1}")
        faces = np.asarray(faces).astype(np.uint32)
    except (KeyError, ValueError, TypeError) as e:
        raise FacecleanError(f"{path.name}: not a face mesh npz ({e})") from None
    out = _arkit_deltas(path.name, vertices, deltas, list(names))
    return FaceMesh(vertices, faces, out, None, path.stem)


def _read_gltf(path: Path) -> FaceMesh:
    """The first mesh whose first primitive has morph targets named in extras.targetNames."""
    from faceclean.io.gltf_container import accessor, parse

    try:  # bounded, buffer URIs confined to the file's folder
        _, _, gltf, _, buffers = parse(path)
    except (IndexError, KeyError, TypeError, AttributeError, ValueError) as e:
        raise FacecleanError(f"{path.name}: not a readable glTF file ({e})") from None
    try:
        for mesh in gltf.meshes or []:
            extras = mesh.extras if isinstance(mesh.extras, dict) else {}
            names = extras.get("targetNames")
            prim = mesh.primitives[0] if mesh.primitives else None
            if not names or prim is None or not prim.targets:
                continue
            vertices = accessor(gltf, buffers, _attr(prim.attributes, "POSITION"))
            if vertices.shape[1] != 3:
                raise FacecleanError("POSITION is not VEC3")
            vertices = vertices.astype(np.float32)
            if prim.indices is None:
                faces = np.arange(len(vertices), dtype=np.uint32).reshape(-1, 3)
            else:
                faces = accessor(gltf, buffers, prim.indices).reshape(-1, 3).astype(np.uint32)
            deltas = np.stack([accessor(gltf, buffers, t["POSITION"]) for t in prim.targets])
            colors = None
            if _attr(prim.attributes, "COLOR_0") is not None:
                colors = accessor(gltf, buffers, _attr(prim.attributes, "COLOR_0"))[:, :3]
                colors = colors.astype(np.float32)
            out = _arkit_deltas(path.name, vertices, deltas, names)
            marks = {str(k): int(v) for k, v in (extras.get("landmarks") or {}).items()}
            return FaceMesh(vertices, faces, out, colors, mesh.name or path.stem, marks)
    except FacecleanError as e:  # the accessor reader's line, named after the file
        raise FacecleanError(f"{path.name}: {e}") from None
    except (KeyError, IndexError, ValueError, TypeError, AttributeError) as e:
        raise FacecleanError(f"{path.name}: unreadable mesh data ({e})") from None
    raise FacecleanError(f"{path.name}: no mesh with named morph targets (extras.targetNames)")


def _attr(attributes: object, name: str) -> int | None:
    """A primitive attribute's accessor index (pygltflib gives an object or a dict)."""
    if isinstance(attributes, dict):
        return attributes.get(name)
    return getattr(attributes, name, None)


def normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals."""
    tri = vertices[faces.astype(np.int64)]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(n, faces[:, k].astype(np.int64), fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.where(length > 0, length, 1), [0.0, 0.0, 1.0])
