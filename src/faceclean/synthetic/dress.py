"""What a real room adds over a face (the ``dressed`` appearance family, scene.py):
spectacles, a cap's brim or a fringe of hair over the forehead, a hand near the face.

``dress(img, lm, scene, index)`` draws over a rendered frame (H, W, 3) float32, display
space, from the 68 landmarks ``lm`` (68, 2) px of the posed head (Multi-PIE order: jaw
0-16, brows 17-26, nose 27-35, eyes 36-47, mouth 48-67). Shapes are soft-edged masks
(``_ellipse``: 1 inside, 0 outside, a 1 px ramp), so they alias no more than the face.
What moves moves slowly with ``index`` (a hand that comes and goes, seeded by the scene).
"""

from __future__ import annotations

import numpy as np

from faceclean.synthetic.scene import Scene

FPS = 30.0  # frames per second the hand's slow motion is timed in


def dress(img: np.ndarray, lm: np.ndarray, s: Scene, index: int) -> np.ndarray:
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    out = img
    eye_r, eye_l = lm[36:42].mean(0), lm[42:48].mean(0)
    span = float(np.linalg.norm(eye_l - eye_r))  # px between the eye centres
    if span < 2:
        return img
    if s.hat:  # a brim / fringe: a dark band from above down over the forehead
        brow = lm[17:27, 1].mean()
        top = brow - 1.1 * span  # the forehead's top, roughly
        edge = top + s.hat * (brow - top)
        tilt = (lm[26, 1] - lm[17, 1]) / max(lm[26, 0] - lm[17, 0], 1.0)
        line = edge + tilt * (xx - lm[17:27, 0].mean())
        band = np.clip(line - yy + 0.5, 0.0, 1.0) * _ellipse(xx, yy, lm[27], 1.6 * span, 3.0 * span)
        colour = np.array(s.hair if s.hair is not None else s.brows) ** (1 / 2.2) * 255.0
        out = _over(out, band, colour)
    if s.glasses:  # two rims and a bridge; faintly tinted lenses
        rim = s.glasses * span
        colour = np.array(s.glasses_colour) ** (1 / 2.2) * 255.0
        for c in (eye_r, eye_l):
            outer = _ellipse(xx, yy, c, 0.45 * span + rim, 0.32 * span + rim)
            inner = _ellipse(xx, yy, c, 0.45 * span, 0.32 * span)
            out = _over(out, inner, 200.0, 0.08)  # the lens
            out = _over(out, outer - inner, colour)
        bridge = _ellipse(xx, yy, (eye_r + eye_l) / 2 - [0, 0.1 * span], 0.12 * span, rim / 2 + 0.5)
        out = _over(out, bridge, colour)
    if s.hand:  # a palm and fingers rising by the jaw, there about half the time
        rng = np.random.default_rng([s.seed, 13])
        phase, side = rng.uniform(0, 6.3), rng.choice([-1, 1])
        up = np.sin(2 * np.pi * 0.07 * index / FPS + phase)  # -1 .. 1
        if up > 0:
            jaw = lm[4] if side < 0 else lm[12]
            chin = lm[8]
            size = s.hand * 2.2 * span
            centre = jaw + (chin - jaw) * 0.3 + np.array([0.0, size * (1.2 - up)])
            mask = _ellipse(xx, yy, centre, 0.5 * size, 0.6 * size)
            for f in range(4):  # fingers fanned up toward the cheek
                tip = centre + np.array([(f - 1.5) * 0.22 * size, -0.95 * size])
                mid = (centre + tip) / 2
                mask = np.maximum(mask, _ellipse(xx, yy, mid, 0.09 * size, 0.45 * size))
            shade = 0.75 + 0.25 * np.clip((yy - centre[1]) / size + 0.5, 0, 1)[..., None]
            colour = (0.9 * np.array(s.skin)) ** (1 / 2.2) * 255.0 * shade
            out = _over(out, mask, colour)
    return out


def _ellipse(xx, yy, c, a: float, b: float) -> np.ndarray:
    """(H, W) soft mask of the ellipse at ``c`` with half-axes a, b px (a 1 px ramp)."""
    a, b = max(a, 0.5), max(b, 0.5)
    r = np.sqrt(((xx - c[0]) / a) ** 2 + ((yy - c[1]) / b) ** 2)  # 1 on the rim
    return np.clip((1.0 - r) * min(a, b) + 0.5, 0.0, 1.0)


def _over(img: np.ndarray, mask: np.ndarray, colour, opacity: float = 1.0) -> np.ndarray:
    m = np.clip(mask, 0.0, 1.0)[..., None] * opacity
    return img * (1.0 - m) + np.asarray(colour, np.float32) * m
