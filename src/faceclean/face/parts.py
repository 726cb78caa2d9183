"""The stylised face's surfaces, posed by :mod:`faceclean.face.rig`; 52 ARKit targets.

Head skin (a warped ellipsoid with a mouth opening and hair coloured on), eyeballs with
iris and pupil, eyelid shells, lip tubes, brows, teeth, tongue, a dark mouth cavity,
ears and neck, each a parametric grid with fixed topology. ``positions(w)`` poses every
vertex for weights w (52,); the morph target of channel j is
``positions(e_j) - positions(0)``, so v = v0 + sum_j w_j delta_j as in any rig.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.face.rig import (
    AX,
    AY,
    AZ,
    EYE_R,
    SIDES,
    W_MOUTH,
    Y_MOUTH,
    Weights,
    brow_disp,
    brow_y,
    eye_centre,
    front_bumps,
    jaw_weight,
    lid_edges,
    lip_disp,
    lip_thickness,
    move_jaw,
    skin_disp,
    skin_z,
    slide,
    smoothstep,
    taper,
)

LID_GRID = (17, 9)  # eyelid vertices: across the eye x from the far edge to the rim
LIP_GRID = (49, 12)  # lip vertices: corner to corner x around the tube

# sRGB-looking palette (faceclean.face.mesh makes it linear for glTF and three.js).
SKIN, HAIR, LIP = (0.93, 0.74, 0.63), (0.24, 0.16, 0.11), (0.78, 0.38, 0.40)
LID, LASH, WHITE = (0.90, 0.68, 0.58), (0.10, 0.07, 0.06), (0.96, 0.96, 0.94)
IRIS, PUPIL, BROW = (0.22, 0.46, 0.62), (0.03, 0.03, 0.04), (0.30, 0.20, 0.13)
TEETH, TONGUE, CAVITY = (0.97, 0.96, 0.90), (0.82, 0.38, 0.42), (0.26, 0.06, 0.08)


def _grid_faces(rows: int, cols: int, wrap: bool = False) -> np.ndarray:
    """(F, 3) triangles of a rows x cols vertex grid (row-major), columns optionally closed."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols if wrap else cols - 1), indexing="ij")
    a = r * cols + c
    b = r * cols + (c + 1) % cols
    quads = np.stack([a, b, a + cols, b + cols], -1).reshape(-1, 4)
    return np.concatenate([quads[:, [0, 2, 1]], quads[:, [1, 2, 3]]])


def _warp(n: int, centre: float, gain: float, width: float) -> np.ndarray:
    """n values in [0, 1], ``gain`` times denser around ``centre``."""
    u = np.linspace(0.0, 1.0, 2001)
    density = 1.0 + (gain - 1.0) * np.exp(-(((u - centre) / width) ** 2))
    cdf = np.concatenate([[0.0], np.cumsum((density[1:] + density[:-1]) / 2)])
    return np.interp(np.linspace(0.0, 1.0, n), cdf / cdf[-1], u)


def _head(g: Weights):
    """Head skin: a warped ellipsoid, hole at the mouth, hair coloured on top and back."""
    rows, cols = 84, 100
    theta = np.pi * (0.012 + 0.976 * _warp(rows, 0.58, 2.4, 0.14))  # rad from the top
    su = np.linspace(-1.0, 1.0, cols, endpoint=False)
    phi = np.pi * (0.5 * su + 0.5 * su**3)  # rad from the front, denser there
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    dx, dy, dz = np.sin(th) * np.sin(ph), np.cos(th), np.sin(th) * np.cos(ph)
    x, y = AX * dx * taper(dy), AY * dy
    z = AZ * dz + smoothstep(0.2, 0.6, dz) * front_bumps(x, y)
    rest = np.stack([x, y, z], -1).reshape(-1, 3)
    rest = np.concatenate([rest, [[0.0, AY, 0.0], [0.0, -AY * 0.97, 0.0]]])  # pole caps
    n = rows * cols
    top = np.stack([np.full(cols, n), (np.arange(cols) + 1) % cols, np.arange(cols)], 1)
    last = (rows - 1) * cols
    bottom = np.stack(
        [np.full(cols, n + 1), last + np.arange(cols), last + (np.arange(cols) + 1) % cols], 1
    )
    faces = np.concatenate([_grid_faces(rows, cols, wrap=True), top, bottom])
    # The mouth: between the lips, drop the faces the jaw would stretch (weights differ).
    follow = jaw_weight(rest)
    centre = rest[faces].mean(1)
    spread = follow[faces].max(1) - follow[faces].min(1)
    hole = (spread > 0.02) & (np.abs(centre[:, 0]) < 0.95 * W_MOUTH) & (centre[:, 2] > 0.05)
    faces = faces[~hole]
    hairline = 0.060 - 0.075 * smoothstep(0.45, -0.6, rest[:, 2] / AZ)
    hair = smoothstep(-0.002, 0.004, rest[:, 1] - hairline)[:, None]
    colors = (1 - hair) * np.array(SKIN) + hair * np.array(HAIR)
    p = rest + skin_disp(rest, g)
    p[:, 2] += smoothstep(0.03, 0.05, rest[:, 2]) * slide(rest, p)
    return move_jaw(p, follow, g), faces, colors


def _sphere(rows: int, cols: int, gamma: np.ndarray | None = None):
    """Unit directions of a sphere with its pole on +z: (rows * cols, 3), faces, gamma (rows,)."""
    gamma = np.linspace(0.0, np.pi, rows) if gamma is None else gamma
    om = np.linspace(0.0, 2 * np.pi, cols, endpoint=False)
    ga, o = np.meshgrid(gamma, om, indexing="ij")
    dirs = np.stack([np.sin(ga) * np.cos(o), np.sin(ga) * np.sin(o), np.cos(ga)], -1)
    return dirs.reshape(-1, 3), _grid_faces(rows, cols, wrap=True), gamma


def _eyes(g: Weights):
    """Eyeballs (pupil and iris rings on the front pole), rotated by the eyeLook shapes."""
    gamma = np.concatenate([[0.0, 0.08, 0.15, 0.175, 0.3, 0.41, 0.44], np.linspace(0.6, np.pi, 12)])
    dirs, faces, gamma = _sphere(len(gamma), 24, gamma)
    ring = np.repeat(gamma, 24)[:, None]
    colors = np.where(ring < 0.16, PUPIL, np.where(ring < 0.42, IRIS, WHITE))
    out = []
    for S, side in SIDES:
        yaw = S * 0.42 * (g("eyeLookOut" + side) - g("eyeLookIn" + side))  # rad, + toward +x
        pitch = 0.35 * (g("eyeLookUp" + side) - g("eyeLookDown" + side))  # rad, + up
        cp, sp, cy, sy = np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
        d = np.stack(
            [dirs[:, 0], cp * dirs[:, 1] + sp * dirs[:, 2], -sp * dirs[:, 1] + cp * dirs[:, 2]], 1
        )
        d = np.stack([cy * d[:, 0] + sy * d[:, 2], d[:, 1], -sy * d[:, 0] + cy * d[:, 2]], 1)
        out.append(eye_centre(S) + EYE_R * d)
    return out, faces, colors


def _lids(g: Weights):
    """Upper and lower eyelids: spherical shells around each eyeball, lash line on the upper."""
    n_beta, n_v, beta_max = LID_GRID[0], LID_GRID[1], np.radians(74)
    beta = np.linspace(-beta_max, beta_max, n_beta)
    v = np.linspace(0.0, 1.0, n_v)
    bb, vv = np.meshgrid(beta, v, indexing="ij")
    faces = _grid_faces(n_beta, n_v)
    profile = (
        np.cos(0.5 * np.pi * bb / beta_max).clip(0.0) ** 0.6
    )  # the edge pinches at the corners
    out, colors = [], []
    for S, side in SIDES:
        upper, lower = lid_edges(S, side, g)
        for edge, far, radius in ((upper, 88.0, 1.12), (lower, -86.0, 1.07)):
            el = np.radians(far + vv * (edge * profile - far))
            r = EYE_R * radius * (1 + 0.04 * vv**4)
            d = np.stack([np.cos(el) * np.sin(bb), np.sin(el), np.cos(el) * np.cos(bb)], -1)
            out.append((eye_centre(S) + r[..., None] * d).reshape(-1, 3))
            rim = LASH if far > 0 else LIP
            c = np.where((vv > 0.9)[..., None], rim, LID).reshape(-1, 3)
            colors.append(c)
    return out, faces, colors


def _lips(g: Weights):
    """Upper and lower lips: tubes along the mouth line, thinner at the corners."""
    n_s, n_r = LIP_GRID
    s = np.linspace(-1.0, 1.0, n_s)
    psi = np.linspace(0.0, 2 * np.pi, n_r, endpoint=False)
    taper = np.maximum(np.sqrt(np.clip(1 - s**2, 0, 1)), 0.2)
    faces = _grid_faces(n_s, n_r, wrap=True)
    out = []
    for upper in (True, False):
        if upper:
            y = Y_MOUTH + 0.0032 * np.sqrt(1 - s**2) - 0.0009 * np.exp(-((s / 0.12) ** 2))
            ry, rz = 0.0030 * taper, 0.0040 * taper
        else:
            y = Y_MOUTH - 0.0036 * np.sqrt(1 - s**2)
            ry, rz = 0.0036 * taper, 0.0045 * taper
        x = W_MOUTH * s
        rest = np.stack([x, y, skin_z(x, y) + 0.2 * rz], 1)
        centre = rest + lip_disp(s, upper, g)
        centre[:, 2] += slide(rest, centre)
        k = lip_thickness(s, upper, g)
        ring = np.stack(
            [np.zeros((n_s, n_r)), np.outer(ry * k, np.cos(psi)), np.outer(rz * k, np.sin(psi))], -1
        )
        p = (centre[:, None, :] + ring).reshape(-1, 3)
        out.append(p if upper else move_jaw(p, np.ones(len(p)), g))
    return out, faces, np.tile(LIP, (n_s * n_r, 1))


def _brows(g: Weights):
    """Brows: flattened tubes lying on the forehead skin."""
    n_t, n_r = 21, 8
    t = np.linspace(0.0, 1.0, n_t)
    psi = np.linspace(0.0, 2 * np.pi, n_r, endpoint=False)
    faces = _grid_faces(n_t, n_r, wrap=True)
    out = []
    for S, side in SIDES:
        x, y = S * (0.012 + 0.040 * t), brow_y(t)
        rest = np.stack([x, y, skin_z(x, y) + 0.0006], 1)
        centre = rest + brow_disp(t, S, side, g)
        centre[:, 2] += slide(rest, centre)
        ry = 0.0032 * (1 - 0.55 * t) + 0.0009
        ring = np.stack(
            [
                np.zeros((n_t, n_r)),
                np.outer(ry, np.cos(psi)),
                np.outer(np.full(n_t, 0.0014), np.sin(psi)),
            ],
            -1,
        )
        out.append((centre[:, None, :] + ring).reshape(-1, 3))
    return out, faces, np.tile(BROW, (n_t * n_r, 1))


def _mouth_inside(g: Weights):
    """Teeth, tongue and the dark cavity cup behind the lips."""
    z_m = float(skin_z(0.0, Y_MOUTH))
    parts = []
    phi = np.radians(np.linspace(-65, 65, 25))
    for radius, depth, top, bottom, follow in (
        (0.020, 0.005, 0.004, -0.0025, 0.0),
        (0.0185, 0.0065, -0.002, -0.008, 1.0),
    ):
        h = np.linspace(top, bottom, 4)
        pp, hh = np.meshgrid(phi, h, indexing="ij")
        p = np.stack(
            [radius * np.sin(pp), Y_MOUTH + hh, z_m - depth - radius + radius * np.cos(pp)], -1
        )
        p = p.reshape(-1, 3)
        parts.append((move_jaw(p, np.full(len(p), follow), g), _grid_faces(25, 4), TEETH))
    dirs, faces, _ = _sphere(10, 16)
    tongue = np.array([0.0, Y_MOUTH - 0.0085, z_m - 0.020]) + dirs * np.array(
        [0.015, 0.0045, 0.016]
    )
    tongue = tongue + g("tongueOut") * np.array([0.0, 0.005, 0.026])
    parts.append((move_jaw(tongue, np.ones(len(tongue)), g), faces, TONGUE))
    gamma = np.linspace(0.0, 0.5 * np.pi, 9)
    dirs, faces, _ = _sphere(9, 20, gamma)
    centre = np.array([0.0, Y_MOUTH - 0.002, z_m - 0.013])
    cup = centre + dirs * np.array([0.018, 0.015, -0.030])  # the back half, open to the front
    lower = smoothstep(0.002, -0.006, cup[:, 1] - centre[1])  # its lower half is the jaw's
    parts.append((move_jaw(cup, lower, g), faces, CAVITY))
    return parts


def _static_parts():
    """Ears and neck: not moved by any shape."""
    parts = []
    dirs, faces, _ = _sphere(8, 12)
    for S, _side in SIDES:
        ear = np.array([S * 0.071, 0.006, -0.010]) + dirs * np.array([0.008, 0.024, 0.015])
        parts.append((ear, faces, SKIN))
    rows, cols = 6, 28
    y = np.linspace(-0.035, -0.13, rows)
    a = np.linspace(0.0, 2 * np.pi, cols, endpoint=False)
    yy, aa = np.meshgrid(y, a, indexing="ij")
    neck = np.stack([0.040 * np.sin(aa), yy, -0.012 + 0.045 * np.cos(aa)], -1).reshape(-1, 3)
    parts.append((neck, _grid_faces(rows, cols, wrap=True), SKIN))
    return parts


def _all_parts(w: np.ndarray):
    """[(vertices (n, 3), faces (f, 3), colours (n, 3) or (3,))] of every surface."""
    g = Weights(w)
    parts = [_head(g)]
    eyes, faces, colors = _eyes(g)
    parts += [(e, faces, colors) for e in eyes]
    lids, faces, colors = _lids(g)
    parts += [(lid, faces, c) for lid, c in zip(lids, colors, strict=True)]
    lips, faces, colors = _lips(g)
    parts += [(lip, faces, colors) for lip in lips]
    brows, faces, colors = _brows(g)
    parts += [(b, faces, colors) for b in brows]
    return parts + _mouth_inside(g) + _static_parts()


def positions(w: np.ndarray) -> np.ndarray:
    """(V, 3) vertex positions in m for weights w (52,), through the full (non-linear) rig."""
    return np.concatenate([p for p, _, _ in _all_parts(w)]).astype(np.float64)


def landmarks() -> dict[str, int]:
    """Vertex indices of the lid rims and lip edges at their middles (for measuring).

    ``upper_lid_left`` / ``lower_lid_left`` (and right): the rims at the eye's centre
    line; ``upper_lip`` / ``lower_lip``: the lips' inner edges at the mouth's middle.
    """
    sizes = [len(p) for p, _, _ in _all_parts(np.zeros(len(ARKIT52)))]
    start = np.concatenate([[0], np.cumsum(sizes)])  # head, 2 eyes, 4 lids, 2 lips, ...
    lid_rim = (LID_GRID[0] // 2) * LID_GRID[1] + LID_GRID[1] - 1
    lip_mid = (LIP_GRID[0] // 2) * LIP_GRID[1]
    return {
        "upper_lid_left": int(start[3] + lid_rim),
        "lower_lid_left": int(start[4] + lid_rim),
        "upper_lid_right": int(start[5] + lid_rim),
        "lower_lid_right": int(start[6] + lid_rim),
        "upper_lip": int(start[7] + lip_mid + LIP_GRID[1] // 2),  # psi = pi: its underside
        "lower_lip": int(start[8] + lip_mid),  # psi = 0: its top
    }


@lru_cache(maxsize=1)
def build() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(neutral (V, 3), faces (F, 3), colours (V, 3), deltas (52, V, 3)) of the stylised face."""
    parts = _all_parts(np.zeros(len(ARKIT52)))
    faces, colors, offset = [], [], 0
    for p, f, c in parts:
        faces.append(f + offset)
        colors.append(np.broadcast_to(np.asarray(c, dtype=np.float64), p.shape))
        offset += len(p)
    neutral = np.concatenate([p for p, _, _ in parts])
    deltas = np.stack([positions(np.eye(len(ARKIT52))[j]) - neutral for j in range(len(ARKIT52))])
    deltas[np.abs(deltas) < 1e-7] = 0.0  # exact zeros where a shape does not reach
    return neutral, np.concatenate(faces), np.concatenate(colors), deltas
