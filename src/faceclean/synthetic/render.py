"""Render one frame: pose the head, light it, rasterise it, and degrade it like a camera.

Camera at the origin looking down -z (y up), the head's pivot ``scene.distance`` cm in
front of it. A vertex p (cm, camera space) lands at pixel
``u = f p_x / -p_z + c_x``, ``v = -f p_y / -p_z + c_y`` with ``f = (size / 2) / tan(fov / 2)``.
Shading (linear RGB, Gouraud): ``albedo (ambient + key max(0, n.l)) + specular max(0, n.h)^24``,
then gamma 1/2.2 per vertex (Gouraud in display space). A portrait's skin (``photo``,
portrait.py) is sampled per pixel at coordinates interpolated like colours, lit about its
own level. Accessories (``dressed``) are drawn over the face (dress.py), grooming
(``groomed``) painted on it (groom.py). The camera:
Gaussian blur (plus motion blur from the head's turn), auto-exposure and white balance,
sensor noise drawn from (seed, frame), JPEG.
"""

from __future__ import annotations

import io as bytes_io
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter

from faceclean.synthetic import head as H
from faceclean.synthetic.head import Head
from faceclean.synthetic.raster import rasterise
from faceclean.synthetic.scene import Scene


@dataclass(eq=False)
class Skin:
    """A portrait fitted to the head (portrait.py): what the renderer textures it with."""

    name: str
    texture: np.ndarray  # (H, W, 3) float32, linear RGB in [0, 1]
    coords: np.ndarray  # (V, 2) float32 px into texture, per rendered vertex
    weight: np.ndarray  # (V,) float32 in [0, 1]: 1 photograph, 0 paint
    alpha: np.ndarray  # (K,) fitted identity
    iris: tuple[float, float, float]  # linear RGB of the portrait's irises


class Renderer:
    """Frames of one take: ``frame(weights, pose_deg, index) -> (size, size, 3) uint8``.
    ``gaze``: the eyeballs turn with the eyeLook weights (gaze.py; off: straight ahead)."""

    def __init__(self, head: Head, scene: Scene, skin: Skin | None = None,
                 gaze: bool = False) -> None:  # fmt: skip
        self.head, self.scene, self.skin = head, scene, skin
        alpha = np.zeros(head.n_identity, np.float32)
        k = min(len(scene.identity), head.n_identity)
        alpha[:k] = scene.identity[:k]
        if skin is not None:  # the portrait's fitted face, varied by the scene's identity
            alpha *= scene.identity_scale
            alpha[: len(skin.alpha)] += skin.alpha
        self.base = head.identity(alpha)  # (V*3,) cm
        self.eyes = None
        if gaze:
            from faceclean.synthetic.gaze import Eyes

            self.eyes = Eyes(head, self.base)
        self.albedo = _albedo(head, scene, skin)  # (V, 3) linear RGB
        self._pose = None  # the last frame's pose (motion blur)
        n = scene.resolution
        self.focal = (n / 2) / np.tan(np.radians(scene.fov) / 2)  # px
        self.centre = np.array([n / 2 * (1 + scene.offset[0]), n / 2 * (1 + scene.offset[1])])
        top, bottom = np.array(scene.background[0]), np.array(scene.background[1])
        ramp = np.linspace(0, 1, n, dtype=np.float32)[:, None, None]
        sky = (top + ramp * (bottom - top)) ** (1 / 2.2) * 255.0
        self.background = np.broadcast_to(sky, (n, n, 3)).astype(np.float32)
        self.light = np.array(scene.light, np.float32)
        self.half = self.light + np.array([0, 0, 1], np.float32)  # Blinn half vector (view +z)
        self.half /= np.linalg.norm(self.half)

    def project(self, weights: np.ndarray, pose_deg: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """(pixel positions (V, 2), depths (V,) cm) of the posed head's vertices."""
        return self._posed(weights, pose_deg)[:2]

    def _posed(self, weights, pose_deg):
        s, hd = self.scene, self.head
        v = hd.vertices(self.base, np.nan_to_num(weights))  # (V, 3) cm, head space
        if self.eyes is not None:
            self.eyes.turn(v, weights)
        r = rotation(*pose_deg)
        p = (v - hd.pivot) @ r.T
        p[:, 2] -= s.distance  # camera space, in front of the camera at -z
        depth = -p[:, 2]
        xy = np.empty((len(p), 2), np.float32)
        xy[:, 0] = self.focal * p[:, 0] / depth + self.centre[0]
        xy[:, 1] = -self.focal * p[:, 1] / depth + self.centre[1]
        return xy, depth, hd.normals(v) @ r.T

    def frame(self, weights: np.ndarray, pose_deg: np.ndarray, index: int) -> np.ndarray:
        s, hd = self.scene, self.head
        xy, depth, nrm = self._posed(weights, pose_deg)
        lambert = np.maximum(nrm @ self.light, 0.0)[:, None]
        spec = np.maximum(nrm @ self.half, 0.0)[:, None] ** 24
        shade = s.ambient + s.key * lambert  # (V, 1)
        colour = self.albedo * shade + s.specular * spec
        colour = np.clip(colour, 0.0, 1.0) ** (1 / 2.2) * 255.0  # gamma per vertex, not pixel
        if self.skin is None:
            img, covered = rasterise(xy, depth, colour, hd.triangles, s.resolution)
        else:  # paint, and the portrait's coordinates, weight and light to sample it with
            k = self.skin
            attrs = np.concatenate([colour, k.coords, k.weight[:, None], shade,
                                    s.specular * spec], axis=1)  # fmt: skip
            img, covered = rasterise(xy, depth, attrs, hd.triangles, s.resolution)
            img = self._texture(img, covered)
        img = np.where(covered[..., None], img, self.background)
        if s.family == "dressed":
            from faceclean.synthetic import dress

            img = dress.dress(img, xy[hd.landmarks], s, index)
        return self._camera(img, index, pose_deg)

    def _texture(self, attrs: np.ndarray, covered: np.ndarray) -> np.ndarray:
        """(size, size, 3) display-space pixels: the portrait sampled (bilinear) at each
        pixel's interpolated coordinates, lit, blended with the paint by its weight."""
        from scipy.ndimage import map_coordinates

        k, s = self.skin, self.scene
        out = attrs[..., :3].copy()
        on = covered & (attrs[..., 5] > 0.01)
        if not on.any():
            return out
        a = attrs[on]  # (P, 8)
        where = [a[:, 4], a[:, 3]]  # (row, column) px
        tex = np.stack([map_coordinates(k.texture[..., c], where, order=1, mode="nearest")
                        for c in range(3)], axis=1)  # fmt: skip
        # the photograph is already lit: our light varies it about its level, not over it
        lit = tex * np.array(s.tint) * (a[:, 6:7] / (s.ambient + 0.6 * s.key)) + a[:, 7:8]
        lit = np.clip(lit, 0.0, 1.0) ** (1 / 2.2) * 255.0
        w = a[:, 5:6]
        out[on] = w * lit + (1.0 - w) * a[:, :3]
        return out

    def _camera(self, img: np.ndarray, index: int, pose_deg: np.ndarray | None = None
                ) -> np.ndarray:  # fmt: skip
        s = self.scene
        blur = s.blur
        if s.motion_blur and pose_deg is not None:  # the turn since the last frame, deg
            if self._pose is not None:
                blur += s.motion_blur * float(np.abs(np.asarray(pose_deg) - self._pose).max())
            self._pose = np.asarray(pose_deg, np.float64).copy()
        if blur > 0:
            img = gaussian_filter(img, sigma=(min(blur, 6.0), min(blur, 6.0), 0))
        if s.exposure or s.white != (1.0, 1.0, 1.0):  # auto-exposure hunting, white balance
            swing = 1.0 + s.exposure * np.sin(2 * np.pi * 0.13 * index / 30.0 + s.seed % 7)
            img = img * (swing * np.array(s.white, np.float32))
        rng = np.random.default_rng([s.seed, 7, index])
        img += s.noise * rng.standard_normal(img.shape, dtype=np.float32)
        frame = np.clip(img + 0.5, 0, 255).astype(np.uint8)
        return jpeg(frame, s.jpeg)


def jpeg(frame: np.ndarray, quality: int) -> np.ndarray:
    """``frame`` (H, W, 3) uint8 through a JPEG encode and decode at ``quality``."""
    from PIL import Image

    buf = bytes_io.BytesIO()
    Image.fromarray(frame).save(buf, format="JPEG", quality=int(quality))
    buf.seek(0)
    return np.asarray(Image.open(buf).convert("RGB"))


def rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """(3, 3) rotation from degrees: yaw about y, pitch about x, roll about z (R = Ry Rx Rz)."""
    y, x, z = np.radians([yaw, pitch, roll])
    cy, sy, cx, sx, cz, sz = np.cos(y), np.sin(y), np.cos(x), np.sin(x), np.cos(z), np.sin(z)
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return (ry @ rx @ rz).astype(np.float32)


def _albedo(head: Head, s: Scene, skin: Skin | None = None) -> np.ndarray:
    """(V, 3) linear RGB per vertex: the painted regions, with a faint per-vertex mottle."""
    rng = np.random.default_rng([s.seed, 3])
    paint = {
        H.SKIN: s.skin,
        H.BACK: np.array(s.brows) * 0.8 if s.hair is None else s.hair,  # hair
        H.MOUTH: (0.35, 0.08, 0.08),
        H.TEETH: (0.75, 0.72, 0.65),
        H.SCLERA: (0.85, 0.82, 0.80),
        H.IRIS: s.iris if skin is None else skin.iris,
        H.PUPIL: (0.02, 0.02, 0.02),
        H.LIPS: s.lips,
        H.BROW: s.brows,
        H.LID: np.array(s.brows) * 0.6,
    }
    table = np.zeros((10, 3), np.float32)
    for code, rgb in paint.items():
        table[code] = rgb
    code = head.regions(s.iris_deg, s.pupil_deg, s.brow_cm, s.lid_cm)  # (V,) paint codes
    albedo = table[code]
    mottle = rng.normal(1.0, 0.04, (len(albedo), 1)).astype(np.float32)
    if s.family == "groomed":
        from faceclean.synthetic import groom

        albedo = groom.paint(head, s, albedo, code)
    return albedo * mottle
