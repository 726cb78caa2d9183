"""The stylised face's geometry and rig: 52 ARKit shapes built by our own code.

Metres, +y up, +z out of the face, +x the face's own left (ARKit: ``...Left`` moves +x).
The face is made of parametric surfaces (head, eyeballs, eyelid shells, lip tubes, brows,
teeth, tongue, mouth cavity, ears, neck). ``positions(w)`` poses every vertex for
weights w (52,) through a small rig (jaw hinge, eyelid edge angles, eye rotation,
displacement fields around the lips, brows and cheeks); the morph target of channel j
is ``positions(e_j) - positions(0)``, so v = v0 + sum_j w_j delta_j as in any rig.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from faceclean.channels import ARKIT52, INDEX

AX, AY, AZ = 0.074, 0.098, 0.088  # m, head ellipsoid semi-axes
Y_MOUTH, W_MOUTH = -0.040, 0.022  # m, mouth line height and half width
EYE_X, EYE_Y, EYE_R = 0.031, 0.026, 0.0125  # m, eye centre (|x|, y) and eyeball radius
SIDES = ((1.0, "Left"), (-1.0, "Right"))
LID_GRID = (17, 9)  # eyelid vertices: across the eye x from the far edge to the rim
LIP_GRID = (49, 12)  # lip vertices: corner to corner x around the tube

SKIN, HAIR, LIP = (0.93, 0.74, 0.63), (0.24, 0.16, 0.11), (0.78, 0.38, 0.40)
LID, LASH, WHITE = (0.90, 0.68, 0.58), (0.10, 0.07, 0.06), (0.96, 0.96, 0.94)
IRIS, PUPIL, BROW = (0.22, 0.46, 0.62), (0.03, 0.03, 0.04), (0.30, 0.20, 0.13)
TEETH, TONGUE, CAVITY = (0.97, 0.96, 0.90), (0.82, 0.38, 0.42), (0.26, 0.06, 0.08)


def _ss(a: float, b: float, x: np.ndarray) -> np.ndarray:
    """Smoothstep from 0 at x = a to 1 at x = b (a > b allowed)."""
    t = np.clip((np.asarray(x, dtype=np.float64) - a) / (b - a), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _gauss(x: np.ndarray, y: np.ndarray, cx: float, cy: float, sx: float, sy: float):
    return np.exp(-(((x - cx) / sx) ** 2) - ((y - cy) / sy) ** 2)


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


def _front_bumps(x: np.ndarray, y: np.ndarray, features: bool = True, sockets: bool = True):
    """Forward (+z) relief of the face in m: muzzle, chin, cheekbones (smooth), and with
    ``features`` the nose, brow ridge and eye sockets."""
    relief = 0.007 * _gauss(x, y, 0.0, -0.042, 0.026, 0.022)  # muzzle
    relief = relief + 0.005 * _gauss(x, y, 0.0, -0.075, 0.016, 0.010)  # chin
    relief = relief + sum(0.004 * _gauss(x, y, s * 0.045, -0.008, 0.014, 0.012) for s, _ in SIDES)
    if not features:
        return relief
    nose_len = np.clip((0.026 - y) / 0.038, 0.0, 1.0)  # 0 at the bridge, 1 at the tip
    nose_w = 0.0055 + 0.0065 * nose_len
    nose = (0.004 + 0.019 * nose_len**1.6) * np.exp(-((x / nose_w) ** 2)) * _ss(-0.024, -0.013, y)
    nose = nose * _ss(0.034, 0.022, y)
    alae = sum(0.006 * _gauss(x, y, s * 0.010, -0.016, 0.006, 0.005) for s, _ in SIDES)
    relief = relief + nose + alae + 0.003 * _gauss(x, y, 0.0, 0.043, 0.05, 0.006)  # brow ridge
    if sockets:
        relief = relief - sum(
            0.008 * _gauss(x, y, s * EYE_X, EYE_Y, 0.013, 0.012) for s, _ in SIDES
        )
    return relief


def skin_z(x: np.ndarray, y: np.ndarray, features: bool = True, sockets: bool = True):
    """z (m) of the neutral face's front surface at (x, y)."""
    dy = np.clip(y / AY, -1.0, 1.0)
    dx = x / (AX * _taper(dy))
    dz = np.sqrt(np.clip(1.0 - dx**2 - dy**2, 0.0, None))
    return AZ * dz + _ss(0.2, 0.6, dz) * _front_bumps(x, y, features, sockets)


def _slide(rest: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """(n,) z change (m) that keeps a point displaced across the face on its smooth
    surface (a sideways move on a curved face would otherwise sink into it)."""
    x0, y0, x1, y1 = rest[:, 0], rest[:, 1], moved[:, 0], moved[:, 1]
    return skin_z(x1, y1, features=False) - skin_z(x0, y0, features=False)


def _taper(dy: np.ndarray) -> np.ndarray:
    """Width scale over height: a narrower jaw and chin, a fuller cranium."""
    return 1.0 - 0.24 * np.clip(-dy, 0.0, None) ** 2 + 0.03 * np.clip(dy, 0.0, None)


class _Weights:
    """Weight lookup by ARKit name."""

    def __init__(self, w: np.ndarray) -> None:
        self.w = np.asarray(w, dtype=np.float64)

    def __call__(self, name: str) -> float:
        return float(self.w[INDEX[name]])


def _jaw(p: np.ndarray, weight: np.ndarray, g: _Weights) -> np.ndarray:
    """Move points by the jaw (hinge near the ears), each by its weight (n,) in [0, 1]."""
    a = 0.30 * g("jawOpen") + 0.11 * g("tongueOut")  # rad, chin down and back
    yaw = 0.02 * (g("jawLeft") - g("jawRight"))  # rad
    hinge = np.array([0.0, 0.012, -0.030])
    q = p - hinge
    c, s = np.cos(a), np.sin(a)
    q = np.stack([q[:, 0], c * q[:, 1] - s * q[:, 2], s * q[:, 1] + c * q[:, 2]], 1)
    cy, sy = np.cos(yaw), np.sin(yaw)
    q = np.stack([cy * q[:, 0] + sy * q[:, 2], q[:, 1], -sy * q[:, 0] + cy * q[:, 2]], 1)
    shift = np.array(
        [
            0.006 * (g("jawLeft") - g("jawRight")),
            -0.004 * g("jawOpen"),
            0.012 * g("jawOpen") + 0.010 * g("jawForward"),
        ]
    )
    moved = q + hinge + shift
    return p + weight[:, None] * (moved - p)


def _lip_disp(s: np.ndarray, upper: bool, g: _Weights) -> np.ndarray:
    """(n, 3) displacement in m of the lip at s in [-1, 1] (right corner -1, left +1)."""
    d = np.zeros((len(s), 3))
    mid = 1.0 - s**4  # lip-only moves vanish at the corners, where both lips meet
    sign = 1.0 if upper else -1.0
    for S, side in SIDES:
        corner = _ss(0.15, 1.0, S * s)[:, None] * (
            g("mouthSmile" + side) * np.array([0.0065 * S, 0.0085, -0.006])
            + g("mouthFrown" + side) * np.array([0.001 * S, -0.0075, -0.001])
            + g("mouthDimple" + side) * np.array([0.0035 * S, 0.0005, -0.005])
            + g("mouthStretch" + side) * np.array([0.0065 * S, -0.004, -0.003])
        )
        d += corner
        half = _ss(-0.35, 0.35, S * s) * mid  # this side of the mouth
        bump = np.exp(-(((s - S * 0.45) / 0.4) ** 2)) * mid
        up_or_down = g("mouthUpperUp" + side) if upper else g("mouthLowerDown" + side)
        d[:, 1] += sign * 0.0075 * up_or_down * bump
        d[:, 1] -= sign * 0.0018 * g("mouthPress" + side) * half
    d[:, 0] += 0.011 * (g("mouthLeft") - g("mouthRight"))
    f, p = g("mouthFunnel"), g("mouthPucker")
    d[:, 0] -= (0.28 * f + 0.42 * p + 0.1 * g("cheekPuff")) * W_MOUTH * s
    d[:, 2] += (0.010 * f + 0.012 * p) * (1.0 - 0.5 * s**2) + 0.002 * g("cheekPuff") * mid
    d[:, 1] += sign * 0.0055 * f * (1.0 - s**2)
    if upper:
        d += g("mouthRollUpper") * np.array([0.0, -0.0022, -0.004]) * mid[:, None]
        d += g("mouthShrugUpper") * np.array([0.0, 0.003, 0.0015]) * mid[:, None]
        d[:, 1] -= 0.003 * g("mouthClose") * mid
    else:
        d += g("mouthRollLower") * np.array([0.0, 0.0022, -0.004]) * mid[:, None]
        d += g("mouthShrugLower") * np.array([0.0, 0.0035, 0.003]) * mid[:, None]
        d += g("mouthClose") * np.array([0.0, 0.014, 0.002]) * mid[:, None]
        d += g("tongueOut") * np.array([0.0, -0.005, 0.002]) * mid[:, None]
    return d


def _lip_thickness(s: np.ndarray, upper: bool, g: _Weights) -> np.ndarray:
    """(n,) scale of the lip's cross-section."""
    k = 1.0 + 0.35 * g("mouthPucker") + 0.15 * g("mouthFunnel")
    k = k - 0.4 * g("mouthRollUpper" if upper else "mouthRollLower")
    for S, side in SIDES:
        k = k - 0.35 * g("mouthPress" + side) * _ss(-0.35, 0.35, S * s)
    return np.clip(k, 0.2, None)


def _brow_y(t: np.ndarray) -> np.ndarray:
    """Rest height (m) of a brow at t in [0, 1] from its inner to its outer end."""
    return 0.047 + 0.005 * np.sin(np.pi * np.clip(t * 1.1, 0.0, 1.0)) - 0.004 * t


def _brow_disp(t: np.ndarray, S: float, side: str, g: _Weights) -> np.ndarray:
    """(n, 3) displacement in m of one brow at t (inner 0 .. outer 1)."""
    d = np.zeros((len(t), 3))
    inner, outer, down = g("browInnerUp"), g("browOuterUp" + side), g("browDown" + side)
    d[:, 1] += 0.011 * inner * (1 - t) ** 1.5 + 0.009 * outer * t**1.3
    d[:, 1] -= 0.008 * down * (1 - 0.35 * t) + 0.0025 * g("noseSneer" + side) * (1 - t)
    d[:, 0] -= S * (0.0015 * inner + 0.003 * down) * (1 - t)
    d[:, 2] += 0.0015 * down * (1 - t)
    return d


def _skin_disp(p: np.ndarray, g: _Weights) -> np.ndarray:
    """(n, 3) displacement of skin points p (n, 3) by the lips, brows, cheeks and nose."""
    x, y = p[:, 0], p[:, 1]
    front = _ss(0.0, 0.04, p[:, 2])
    s = np.clip(x / W_MOUTH, -1.0, 1.0)
    beyond = np.exp(-(((np.abs(x) - W_MOUTH).clip(0.0) / 0.016) ** 2))
    upper = y >= Y_MOUTH
    d = np.zeros_like(p)
    for is_upper, mask in ((True, upper), (False, ~upper)):
        sigma = 0.013 if is_upper else 0.016
        fall = np.exp(-(((y[mask] - Y_MOUTH) / sigma) ** 2)) * beyond[mask]
        d[mask] = _lip_disp(s[mask], is_upper, g) * fall[:, None]
    for S, side in SIDES:
        t = np.clip((S * x - 0.012) / 0.040, 0.0, 1.0)
        dy = y - _brow_y(t)
        fall = np.exp(-((dy / np.where(dy > 0, 0.018, 0.007)) ** 2))
        fall *= np.exp(-(((0.012 - S * x).clip(0.0) / 0.010) ** 2))
        fall *= np.exp(-(((S * x - 0.052).clip(0.0) / 0.012) ** 2))
        d += _brow_disp(t, S, side, g) * fall[:, None]
        out = np.array([S * 0.85, -0.1, 0.5])
        d += g("cheekPuff") * 0.016 * _gauss(x, y, S * 0.040, -0.034, 0.019, 0.022)[:, None] * out
        cheek = _gauss(x, y, S * 0.038, -0.002, 0.015, 0.012)
        d += g("cheekSquint" + side) * cheek[:, None] * np.array([0.0, 0.005, 0.002])
        raise_ = _gauss(x, y, S * 0.036, -0.014, 0.016, 0.014)
        d += g("mouthSmile" + side) * raise_[:, None] * np.array([S * 0.001, 0.004, 0.003])
        wing = _gauss(x, y, S * 0.011, -0.010, 0.008, 0.012)
        d += g("noseSneer" + side) * wing[:, None] * np.array([-S * 0.001, 0.006, 0.001])
    return d * front[:, None]


def _jaw_weight(p: np.ndarray) -> np.ndarray:
    """(n,) how much each skin point follows the jaw: below the mouth, front and lower head."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    lips = np.maximum(0.0022 * np.sqrt(np.clip(1 - (x / W_MOUTH) ** 2, 0, 1)), 0.0008)
    h = lips + 0.03 * _ss(0.8 * W_MOUTH, 2.4 * W_MOUTH, np.abs(x))  # m, half the ramp
    return _ss(-h, h, Y_MOUTH - y) * _ss(-0.045, 0.0, z)


def _head(g: _Weights):
    """Head skin: a warped ellipsoid, hole at the mouth, hair coloured on top and back."""
    rows, cols = 84, 100
    theta = np.pi * (0.012 + 0.976 * _warp(rows, 0.58, 2.4, 0.14))  # rad from the top
    su = np.linspace(-1.0, 1.0, cols, endpoint=False)
    phi = np.pi * (0.5 * su + 0.5 * su**3)  # rad from the front, denser there
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    dx, dy, dz = np.sin(th) * np.sin(ph), np.cos(th), np.sin(th) * np.cos(ph)
    x, y = AX * dx * _taper(dy), AY * dy
    z = AZ * dz + _ss(0.2, 0.6, dz) * _front_bumps(x, y)
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
    jaw = _jaw_weight(rest)
    centre = rest[faces].mean(1)
    spread = jaw[faces].max(1) - jaw[faces].min(1)
    hole = (spread > 0.02) & (np.abs(centre[:, 0]) < 0.95 * W_MOUTH) & (centre[:, 2] > 0.05)
    faces = faces[~hole]
    hairline = 0.060 - 0.075 * _ss(0.45, -0.6, rest[:, 2] / AZ)
    hair = _ss(-0.002, 0.004, rest[:, 1] - hairline)[:, None]
    colors = (1 - hair) * np.array(SKIN) + hair * np.array(HAIR)
    p = rest + _skin_disp(rest, g)
    p[:, 2] += _ss(0.03, 0.05, rest[:, 2]) * _slide(rest, p)
    return _jaw(p, jaw, g), faces, colors


def _sphere(rows: int, cols: int, gamma: np.ndarray | None = None):
    """Unit directions of a sphere with its pole on +z: (rows * cols, 3), faces, gamma (rows,)."""
    gamma = np.linspace(0.0, np.pi, rows) if gamma is None else gamma
    om = np.linspace(0.0, 2 * np.pi, cols, endpoint=False)
    ga, o = np.meshgrid(gamma, om, indexing="ij")
    dirs = np.stack([np.sin(ga) * np.cos(o), np.sin(ga) * np.sin(o), np.cos(ga)], -1)
    return dirs.reshape(-1, 3), _grid_faces(rows, cols, wrap=True), gamma


def eye_centre(S: float) -> np.ndarray:
    """Centre (m) of the eyeball on side S (+1 left, -1 right)."""
    return np.array([S * EYE_X, EYE_Y, float(skin_z(S * EYE_X, EYE_Y, sockets=False)) - 0.0085])


def _eyes(g: _Weights):
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


def _lid_edges(S: float, side: str, g: _Weights) -> tuple[float, float]:
    """Elevation (deg) of the upper and lower eyelid edges at the eye's centre line."""
    blink, squint, wide = g("eyeBlink" + side), g("eyeSquint" + side), g("eyeWide" + side)
    up, down, cheek = g("eyeLookUp" + side), g("eyeLookDown" + side), g("cheekSquint" + side)
    upper = 34 + 24 * wide - 64 * blink - 12 * squint + 10 * up - 18 * down - 4 * cheek
    lower = -30 + 18 * squint + 12 * cheek + 6 * g("mouthSmile" + side) - 6 * wide
    return upper, lower + 4 * blink - 6 * down + 4 * up


def _lids(g: _Weights):
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
        upper, lower = _lid_edges(S, side, g)
        for edge, far, radius in ((upper, 88.0, 1.12), (lower, -86.0, 1.07)):
            el = np.radians(far + vv * (edge * profile - far))
            r = EYE_R * radius * (1 + 0.04 * vv**4)
            d = np.stack([np.cos(el) * np.sin(bb), np.sin(el), np.cos(el) * np.cos(bb)], -1)
            out.append((eye_centre(S) + r[..., None] * d).reshape(-1, 3))
            rim = LASH if far > 0 else LIP
            c = np.where((vv > 0.9)[..., None], rim, LID).reshape(-1, 3)
            colors.append(c)
    return out, faces, colors


def _lips(g: _Weights):
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
        centre = rest + _lip_disp(s, upper, g)
        centre[:, 2] += _slide(rest, centre)
        k = _lip_thickness(s, upper, g)
        ring = np.stack(
            [np.zeros((n_s, n_r)), np.outer(ry * k, np.cos(psi)), np.outer(rz * k, np.sin(psi))], -1
        )
        p = (centre[:, None, :] + ring).reshape(-1, 3)
        out.append(p if upper else _jaw(p, np.ones(len(p)), g))
    return out, faces, np.tile(LIP, (n_s * n_r, 1))


def _brows(g: _Weights):
    """Brows: flattened tubes lying on the forehead skin."""
    n_t, n_r = 21, 8
    t = np.linspace(0.0, 1.0, n_t)
    psi = np.linspace(0.0, 2 * np.pi, n_r, endpoint=False)
    faces = _grid_faces(n_t, n_r, wrap=True)
    out = []
    for S, side in SIDES:
        x, y = S * (0.012 + 0.040 * t), _brow_y(t)
        rest = np.stack([x, y, skin_z(x, y) + 0.0006], 1)
        centre = rest + _brow_disp(t, S, side, g)
        centre[:, 2] += _slide(rest, centre)
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


def _mouth_inside(g: _Weights):
    """Teeth, tongue and the dark cavity cup behind the lips."""
    z_m = float(skin_z(0.0, Y_MOUTH))
    parts = []
    phi = np.radians(np.linspace(-65, 65, 25))
    for radius, depth, top, bottom, jaw in (
        (0.020, 0.005, 0.004, -0.0025, 0.0),
        (0.0185, 0.0065, -0.002, -0.008, 1.0),
    ):
        h = np.linspace(top, bottom, 4)
        pp, hh = np.meshgrid(phi, h, indexing="ij")
        p = np.stack(
            [radius * np.sin(pp), Y_MOUTH + hh, z_m - depth - radius + radius * np.cos(pp)], -1
        )
        p = p.reshape(-1, 3)
        parts.append((_jaw(p, np.full(len(p), jaw), g), _grid_faces(25, 4), TEETH))
    dirs, faces, _ = _sphere(10, 16)
    tongue = np.array([0.0, Y_MOUTH - 0.0085, z_m - 0.020]) + dirs * np.array(
        [0.015, 0.0045, 0.016]
    )
    tongue = tongue + g("tongueOut") * np.array([0.0, 0.005, 0.026])
    parts.append((_jaw(tongue, np.ones(len(tongue)), g), faces, TONGUE))
    gamma = np.linspace(0.0, 0.5 * np.pi, 9)
    dirs, faces, _ = _sphere(9, 20, gamma)
    centre = np.array([0.0, Y_MOUTH - 0.002, z_m - 0.013])
    cup = centre + dirs * np.array([0.018, 0.015, -0.030])  # the back half, open to the front
    parts.append((_jaw(cup, _ss(0.002, -0.006, cup[:, 1] - centre[1]), g), faces, CAVITY))
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
    g = _Weights(w)
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
