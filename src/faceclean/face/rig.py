"""The stylised face's rig: how the 52 ARKit weights move its surface, eyes and mouth.

Metres, +y up, +z out of the face, +x the face's own left (ARKit: ``...Left`` moves +x).
The face's front surface is an ellipsoid with relief (``skin_z``); the rig moves points
of it through a jaw hinge, eyelid edge angles, eye rotations and smooth displacement
fields around the lips, brows, cheeks and nose. The surfaces themselves are built in
:mod:`faceclean.face.parts`.
"""

from __future__ import annotations

import numpy as np

from faceclean.channels import INDEX

AX, AY, AZ = 0.074, 0.098, 0.088  # m, head ellipsoid semi-axes
Y_MOUTH, W_MOUTH = -0.040, 0.022  # m, mouth line height and half width
EYE_X, EYE_Y, EYE_R = 0.031, 0.026, 0.0125  # m, eye centre (|x|, y) and eyeball radius
SIDES = ((1.0, "Left"), (-1.0, "Right"))


def smoothstep(a: float, b: float, x: np.ndarray) -> np.ndarray:
    """Smoothstep from 0 at x = a to 1 at x = b (a > b allowed)."""
    t = np.clip((np.asarray(x, dtype=np.float64) - a) / (b - a), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def gauss(x: np.ndarray, y: np.ndarray, cx: float, cy: float, sx: float, sy: float):
    return np.exp(-(((x - cx) / sx) ** 2) - ((y - cy) / sy) ** 2)


def front_bumps(x: np.ndarray, y: np.ndarray, features: bool = True, sockets: bool = True):
    """Forward (+z) relief of the face in m: muzzle, chin, cheekbones (smooth), and with
    ``features`` the nose, brow ridge and eye sockets."""
    relief = 0.007 * gauss(x, y, 0.0, -0.042, 0.026, 0.022)  # muzzle
    relief = relief + 0.005 * gauss(x, y, 0.0, -0.075, 0.016, 0.010)  # chin
    relief = relief + sum(0.004 * gauss(x, y, s * 0.045, -0.008, 0.014, 0.012) for s, _ in SIDES)
    if not features:
        return relief
    nose_len = np.clip((0.026 - y) / 0.038, 0.0, 1.0)  # 0 at the bridge, 1 at the tip
    nose_w = 0.0055 + 0.0065 * nose_len
    nose = (
        (0.004 + 0.019 * nose_len**1.6)
        * np.exp(-((x / nose_w) ** 2))
        * smoothstep(-0.024, -0.013, y)
    )
    nose = nose * smoothstep(0.034, 0.022, y)
    alae = sum(0.006 * gauss(x, y, s * 0.010, -0.016, 0.006, 0.005) for s, _ in SIDES)
    relief = relief + nose + alae + 0.003 * gauss(x, y, 0.0, 0.043, 0.05, 0.006)  # brow ridge
    if sockets:
        relief = relief - sum(0.008 * gauss(x, y, s * EYE_X, EYE_Y, 0.013, 0.012) for s, _ in SIDES)
    return relief


def skin_z(x: np.ndarray, y: np.ndarray, features: bool = True, sockets: bool = True):
    """z (m) of the neutral face's front surface at (x, y)."""
    dy = np.clip(y / AY, -1.0, 1.0)
    dx = x / (AX * taper(dy))
    dz = np.sqrt(np.clip(1.0 - dx**2 - dy**2, 0.0, None))
    return AZ * dz + smoothstep(0.2, 0.6, dz) * front_bumps(x, y, features, sockets)


def slide(rest: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """(n,) z change (m) that keeps a point displaced across the face on its smooth
    surface (a sideways move on a curved face would otherwise sink into it)."""
    x0, y0, x1, y1 = rest[:, 0], rest[:, 1], moved[:, 0], moved[:, 1]
    return skin_z(x1, y1, features=False) - skin_z(x0, y0, features=False)


def taper(dy: np.ndarray) -> np.ndarray:
    """Width scale over height: a narrower jaw and chin, a fuller cranium."""
    return 1.0 - 0.24 * np.clip(-dy, 0.0, None) ** 2 + 0.03 * np.clip(dy, 0.0, None)


class Weights:
    """Weight lookup by ARKit name."""

    def __init__(self, w: np.ndarray) -> None:
        self.w = np.asarray(w, dtype=np.float64)

    def __call__(self, name: str) -> float:
        return float(self.w[INDEX[name]])


def move_jaw(p: np.ndarray, weight: np.ndarray, g: Weights) -> np.ndarray:
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


def lip_disp(s: np.ndarray, upper: bool, g: Weights) -> np.ndarray:
    """(n, 3) displacement in m of the lip at s in [-1, 1] (right corner -1, left +1)."""
    d = np.zeros((len(s), 3))
    mid = 1.0 - s**4  # lip-only moves vanish at the corners, where both lips meet
    sign = 1.0 if upper else -1.0
    for S, side in SIDES:
        corner = smoothstep(0.15, 1.0, S * s)[:, None] * (
            g("mouthSmile" + side) * np.array([0.0065 * S, 0.0085, -0.006])
            + g("mouthFrown" + side) * np.array([0.001 * S, -0.0075, -0.001])
            + g("mouthDimple" + side) * np.array([0.0035 * S, 0.0005, -0.005])
            + g("mouthStretch" + side) * np.array([0.0065 * S, -0.004, -0.003])
        )
        d += corner
        half = smoothstep(-0.35, 0.35, S * s) * mid  # this side of the mouth
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


def lip_thickness(s: np.ndarray, upper: bool, g: Weights) -> np.ndarray:
    """(n,) scale of the lip's cross-section."""
    k = 1.0 + 0.35 * g("mouthPucker") + 0.15 * g("mouthFunnel")
    k = k - 0.4 * g("mouthRollUpper" if upper else "mouthRollLower")
    for S, side in SIDES:
        k = k - 0.35 * g("mouthPress" + side) * smoothstep(-0.35, 0.35, S * s)
    return np.clip(k, 0.2, None)


def brow_y(t: np.ndarray) -> np.ndarray:
    """Rest height (m) of a brow at t in [0, 1] from its inner to its outer end."""
    return 0.047 + 0.005 * np.sin(np.pi * np.clip(t * 1.1, 0.0, 1.0)) - 0.004 * t


def brow_disp(t: np.ndarray, S: float, side: str, g: Weights) -> np.ndarray:
    """(n, 3) displacement in m of one brow at t (inner 0 .. outer 1)."""
    d = np.zeros((len(t), 3))
    inner, outer, down = g("browInnerUp"), g("browOuterUp" + side), g("browDown" + side)
    d[:, 1] += 0.011 * inner * (1 - t) ** 1.5 + 0.009 * outer * t**1.3
    d[:, 1] -= 0.008 * down * (1 - 0.35 * t) + 0.0025 * g("noseSneer" + side) * (1 - t)
    d[:, 0] -= S * (0.0015 * inner + 0.003 * down) * (1 - t)
    d[:, 2] += 0.0015 * down * (1 - t)
    return d


def skin_disp(p: np.ndarray, g: Weights) -> np.ndarray:
    """(n, 3) displacement of skin points p (n, 3) by the lips, brows, cheeks and nose."""
    x, y = p[:, 0], p[:, 1]
    front = smoothstep(0.0, 0.04, p[:, 2])
    s = np.clip(x / W_MOUTH, -1.0, 1.0)
    beyond = np.exp(-(((np.abs(x) - W_MOUTH).clip(0.0) / 0.016) ** 2))
    upper = y >= Y_MOUTH
    d = np.zeros_like(p)
    for is_upper, mask in ((True, upper), (False, ~upper)):
        sigma = 0.013 if is_upper else 0.016
        fall = np.exp(-(((y[mask] - Y_MOUTH) / sigma) ** 2)) * beyond[mask]
        d[mask] = lip_disp(s[mask], is_upper, g) * fall[:, None]
    for S, side in SIDES:
        t = np.clip((S * x - 0.012) / 0.040, 0.0, 1.0)
        dy = y - brow_y(t)
        fall = np.exp(-((dy / np.where(dy > 0, 0.018, 0.007)) ** 2))
        fall *= np.exp(-(((0.012 - S * x).clip(0.0) / 0.010) ** 2))
        fall *= np.exp(-(((S * x - 0.052).clip(0.0) / 0.012) ** 2))
        d += brow_disp(t, S, side, g) * fall[:, None]
        out = np.array([S * 0.85, -0.1, 0.5])
        d += g("cheekPuff") * 0.016 * gauss(x, y, S * 0.040, -0.034, 0.019, 0.022)[:, None] * out
        cheek = gauss(x, y, S * 0.038, -0.002, 0.015, 0.012)
        d += g("cheekSquint" + side) * cheek[:, None] * np.array([0.0, 0.005, 0.002])
        raise_ = gauss(x, y, S * 0.036, -0.014, 0.016, 0.014)
        d += g("mouthSmile" + side) * raise_[:, None] * np.array([S * 0.001, 0.004, 0.003])
        wing = gauss(x, y, S * 0.011, -0.010, 0.008, 0.012)
        d += g("noseSneer" + side) * wing[:, None] * np.array([-S * 0.001, 0.006, 0.001])
    return d * front[:, None]


def jaw_weight(p: np.ndarray) -> np.ndarray:
    """(n,) how much each skin point follows the jaw: below the mouth, front and lower head."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    lips = np.maximum(0.0022 * np.sqrt(np.clip(1 - (x / W_MOUTH) ** 2, 0, 1)), 0.0008)
    h = lips + 0.03 * smoothstep(0.8 * W_MOUTH, 2.4 * W_MOUTH, np.abs(x))  # m, half the ramp
    return smoothstep(-h, h, Y_MOUTH - y) * smoothstep(-0.045, 0.0, z)


def eye_centre(S: float) -> np.ndarray:
    """Centre (m) of the eyeball on side S (+1 left, -1 right)."""
    return np.array([S * EYE_X, EYE_Y, float(skin_z(S * EYE_X, EYE_Y, sockets=False)) - 0.0085])


def lid_edges(S: float, side: str, g: Weights) -> tuple[float, float]:
    """Elevation (deg) of the upper and lower eyelid edges at the eye's centre line."""
    blink, squint, wide = g("eyeBlink" + side), g("eyeSquint" + side), g("eyeWide" + side)
    up, down, cheek = g("eyeLookUp" + side), g("eyeLookDown" + side), g("cheekSquint" + side)
    upper = 34 + 24 * wide - 64 * blink - 12 * squint + 10 * up - 18 * down - 4 * cheek
    lower = -30 + 18 * squint + 12 * cheek + 6 * g("mouthSmile" + side) - 6 * wide
    return upper, lower + 4 * blink - 6 * down + 4 * up
