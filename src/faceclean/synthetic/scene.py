"""Scene: every randomised factor of one rendered take, a plain record drawn from a seed.

A scene is fixed for a whole take (a person sits in one room before one camera); what
changes per frame is the expression (the take's ARKit weights), the head pose and the
sensor noise, which is drawn from ``(seed, frame index)``, so any frame can be rebuilt
from the scene and its index alone.

Render settings are families of scenes. Training draws from some and evaluation holds one
out, so a model is judged on lighting and cameras it never saw:

- ``studio``: soft frontal light, a good camera close by, little noise;
- ``webcam``: a laptop camera at arm's length, flat light, noise and strong JPEG;
- ``window``: a hard side light from one window, shadows on half the face, mid noise.

Appearance families are the other axis: what the face itself looks like. Training holds
one family out and scores on it (docs/MODEL.md), so a model is judged on a *look* it
never saw:

- ``painted``: the ICT head painted per vertex (head.py), its iris, pupil, brows, lid
  margins, hair and skin shine drawn per scene;
- ``photo``: the head fitted to a real portrait and textured from it (portrait.py): real
  skin, brows, lashes, spectacles where the person wore them;
- ``dressed``: the painted head in a real room: spectacles, a cap's brim or a fringe of
  hair, a hand near the face, a camera's auto-exposure and white balance wandering,
  motion blur, harder compression (dress.py);
- ``groomed``: the painted head groomed (groom.py): eyeliner and eyeshadow, a beard or
  stubble, freckles, lipstick, oilier skin: contrast where MediaPipe reads lids and lips.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from faceclean.errors import FacecleanError

# per setting: (light elevation deg range, azimuth deg range, key light, fill/ambient,
#               distance cm, field of view deg, resolution px, noise sigma /255,
#               blur sigma px, JPEG quality)
SETTINGS: dict[str, dict[str, tuple[float, float]]] = {
    "studio": dict(
        elevation=(10, 40),
        azimuth=(-25, 25),
        key=(0.6, 0.8),
        ambient=(0.35, 0.5),
        distance=(45, 70),
        fov=(35, 50),
        resolution=(320, 448),
        noise=(0.5, 2.5),
        blur=(0.3, 0.8),
        jpeg=(85, 95),
    ),
    "webcam": dict(
        elevation=(-5, 25),
        azimuth=(-35, 35),
        key=(0.45, 0.7),
        ambient=(0.4, 0.6),
        distance=(55, 90),
        fov=(55, 75),
        resolution=(256, 384),
        noise=(2.0, 6.0),
        blur=(0.6, 1.4),
        jpeg=(45, 75),
    ),
    "window": dict(
        elevation=(0, 30),
        azimuth=(50, 80),
        key=(0.8, 1.0),
        ambient=(0.15, 0.3),
        distance=(45, 80),
        fov=(40, 60),
        resolution=(288, 416),
        noise=(1.5, 4.0),
        blur=(0.4, 1.0),
        jpeg=(65, 90),
    ),
}
TRAIN_SETTINGS = ("studio", "webcam")
HELD_OUT_SETTING = "window"
FAMILIES = ("painted", "photo", "dressed", "groomed")

# skin albedo (linear RGB) from light to dark: a person's tone is drawn along this line
SKIN_TONES = np.array(
    [[0.80, 0.62, 0.52], [0.72, 0.52, 0.40], [0.56, 0.38, 0.27], [0.36, 0.22, 0.15]]
)
IRIS_COLOURS = np.array(
    [[0.30, 0.18, 0.08], [0.15, 0.09, 0.04], [0.25, 0.35, 0.50], [0.30, 0.40, 0.25]]
)


@dataclass(frozen=True)
class Scene:
    seed: int
    setting: str
    identity: tuple[float, ...]  # ICT identity weights, ~ N(0, 1)
    skin: tuple[float, float, float]  # linear RGB albedo
    lips: tuple[float, float, float]
    brows: tuple[float, float, float]
    iris: tuple[float, float, float]
    light: tuple[float, float, float]  # unit vector towards the key light, camera space
    key: float  # key light intensity
    ambient: float
    specular: float
    background: tuple[tuple[float, float, float], tuple[float, float, float]]  # top, bottom
    distance: float  # cm, camera to head pivot
    fov: float  # deg, vertical field of view
    resolution: int  # px, square frame
    noise: float  # sensor noise sigma, in 0..255 units
    blur: float  # px, Gaussian sigma (optics and motion)
    jpeg: int  # quality 1..100
    offset: tuple[float, float]  # where the head sits in the frame, fraction of the width
    pose_drift: float  # deg, amplitude of the head's wander when the take has no pose
    # the look (FAMILIES); the defaults are the painted head as it was first drawn
    family: str = "painted"
    iris_deg: float = 21.0  # iris half-angle on the eyeball
    pupil_deg: float = 8.0
    brow_cm: float = 0.45  # brow half-width
    lid_cm: float = 0.18  # lash line width
    hair: tuple[float, float, float] | None = None  # None: the brows' colour x 0.8
    portrait: str = ""  # photo: the portrait's name (portrait.py)
    flip: bool = False  # photo: the portrait mirrored
    identity_scale: float = 1.0  # photo: the fitted identity + this x the drawn one
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)  # photo: gains on the texture
    white: tuple[float, float, float] = (1.0, 1.0, 1.0)  # camera white balance gains
    exposure: float = 0.0  # auto-exposure swing, fraction of the level
    motion_blur: float = 0.0  # px of blur per deg of head turn in a frame
    glasses: float = 0.0  # rim width, fraction of the eye's width; 0: none
    glasses_colour: tuple[float, float, float] = (0.05, 0.05, 0.05)
    hat: float = 0.0  # how far a brim or fringe comes down, fraction of forehead; 0: none
    hand: float = 0.0  # a hand near the face, its size in face widths; 0: none
    liner: float = 0.0  # groomed: eyeliner width, cm from the lid contour; 0: none
    shadow: float = 0.0  # groomed: eyeshadow strength in [0, 1]; 0: none
    shadow_colour: tuple[float, float, float] = (0.2, 0.12, 0.1)
    beard: float = 0.0  # groomed: beard density in [0, 1] (stubble under 0.5); 0: none
    freckles: float = 0.0  # groomed: share of the front skin's vertices darkened
    lipstick: tuple[float, float, float] | None = None  # groomed: the lips' colour

    @classmethod
    def draw(cls, seed: int, setting: str, n_identity: int = 100, family: str = "painted",
             portraits: tuple[str, ...] = ()) -> Scene:  # fmt: skip
        """The scene of ``seed`` in ``setting`` and ``family`` (``photo`` draws one of
        ``portraits``, the names of the portraits at hand)."""
        if setting not in SETTINGS:
            raise FacecleanError(
                f"unknown render setting {setting!r} (one of: {', '.join(SETTINGS)})"
            )
        if family not in FAMILIES:
            raise FacecleanError(
                f"unknown appearance family {family!r} (one of: {', '.join(FAMILIES)})"
            )
        if family == "photo" and not portraits:
            raise FacecleanError("the photo family needs portraits (faceclean pairs --portraits)")
        return replace(
            cls._draw(seed, setting, n_identity), **_look(seed, setting, family, portraits)
        )

    @classmethod
    def _draw(cls, seed: int, setting: str, n_identity: int) -> Scene:
        s = SETTINGS[setting]
        rng = np.random.default_rng([seed, list(SETTINGS).index(setting)])

        def u(key: str) -> float:
            lo, hi = s[key]
            return float(rng.uniform(lo, hi))

        tone = rng.uniform(0, len(SKIN_TONES) - 1)
        i = min(int(tone), len(SKIN_TONES) - 2)
        skin = SKIN_TONES[i] + (tone - i) * (SKIN_TONES[i + 1] - SKIN_TONES[i])
        skin = skin * rng.uniform(0.92, 1.08, 3)
        lips = skin * np.array([1.0, 0.62, 0.62]) * rng.uniform(0.7, 0.95)
        brows = skin * rng.uniform(0.15, 0.45)
        iris = IRIS_COLOURS[rng.integers(len(IRIS_COLOURS))] * rng.uniform(0.7, 1.3)
        el, az = np.radians(u("elevation")), np.radians(u("azimuth")) * rng.choice([-1, 1])
        light = (np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az))
        top = rng.uniform(0.1, 0.9, 3)
        bottom = np.clip(top * rng.uniform(0.5, 1.2, 3), 0, 1)
        return cls(
            seed=int(seed),
            setting=setting,
            identity=tuple(float(a) for a in rng.standard_normal(n_identity)),
            skin=_t(skin),
            lips=_t(lips),
            brows=_t(brows),
            iris=_t(np.clip(iris, 0, 1)),
            light=_t(light),
            key=u("key"),
            ambient=u("ambient"),
            specular=float(rng.uniform(0.02, 0.12)),
            background=(_t(top), _t(bottom)),
            distance=u("distance"),
            fov=u("fov"),
            resolution=int(round(u("resolution") / 16) * 16),
            noise=u("noise"),
            blur=u("blur"),
            jpeg=int(round(u("jpeg"))),
            offset=(float(rng.uniform(-0.06, 0.06)), float(rng.uniform(-0.06, 0.06))),
            pose_drift=float(rng.uniform(3.0, 12.0)),
        )

    def record(self) -> dict:
        """The scene as plain JSON-ready values (the pair file's metadata logs it)."""
        d = asdict(self)
        d["identity"] = [round(a, 6) for a in self.identity]
        return d


def _look(seed: int, setting: str, family: str, portraits: tuple[str, ...]) -> dict:
    """The family's own draws, from a stream of their own (the scene's other draws stay)."""
    rng = np.random.default_rng([seed, list(SETTINGS).index(setting), 100 + FAMILIES.index(family)])
    u = rng.uniform
    look: dict = {"family": family}
    if family in ("painted", "dressed", "groomed"):
        look.update(iris_deg=u(17.0, 24.0), pupil_deg=u(5.5, 9.5), brow_cm=u(0.28, 0.65),
                    lid_cm=u(0.1, 0.3), specular=u(0.02, 0.3),
                    hair=_t(rng.choice(HAIR) * u(0.6, 1.3)))  # fmt: skip
    if family == "photo":
        look.update(portrait=str(portraits[rng.integers(len(portraits))]),
                    flip=bool(rng.random() < 0.5), identity_scale=u(0.0, 0.5),
                    tint=_t(u(0.85, 1.15, 3)), specular=u(0.0, 0.08))  # fmt: skip
    if family == "dressed":
        look.update(
            white=_t(u(0.8, 1.2, 3)),
            exposure=u(0.05, 0.3),
            motion_blur=u(0.3, 1.5),
            glasses=u(0.05, 0.15) if rng.random() < 0.6 else 0.0,
            glasses_colour=_t(rng.choice(FRAMES) * u(0.7, 1.3)),
            hat=u(0.2, 0.8) if rng.random() < 0.5 else 0.0,
            hand=u(0.3, 0.6) if rng.random() < 0.5 else 0.0,
        )
    if family == "groomed":  # each part of it about half the time, drawn apart
        look.update(
            liner=u(0.2, 0.45) if rng.random() < 0.5 else 0.0,
            shadow=u(0.3, 0.8) if rng.random() < 0.4 else 0.0,
            shadow_colour=_t(rng.choice(SHADOWS) * u(0.7, 1.3)),
            beard=u(0.2, 0.95) if rng.random() < 0.5 else 0.0,
            freckles=u(0.05, 0.25) if rng.random() < 0.3 else 0.0,
            lipstick=_t(rng.choice(LIPSTICKS) * u(0.8, 1.2)) if rng.random() < 0.4 else None,
            specular=u(0.1, 0.45),  # oily skin's shine
        )
    return look


HAIR = np.array([[0.03, 0.02, 0.015], [0.12, 0.07, 0.04], [0.35, 0.22, 0.1], [0.6, 0.5, 0.3],
                 [0.45, 0.15, 0.06], [0.4, 0.4, 0.4]])  # fmt: skip
SHADOWS = np.array([[0.2, 0.12, 0.1], [0.1, 0.1, 0.18], [0.3, 0.2, 0.3], [0.05, 0.05, 0.05]])
LIPSTICKS = np.array([[0.45, 0.03, 0.05], [0.6, 0.2, 0.3], [0.2, 0.04, 0.08], [0.55, 0.35, 0.3]])
FRAMES = np.array([[0.04, 0.04, 0.04], [0.3, 0.15, 0.05], [0.6, 0.6, 0.62], [0.5, 0.1, 0.1]])


def _t(a) -> tuple[float, ...]:
    return tuple(float(x) for x in np.asarray(a, np.float64).reshape(-1))
