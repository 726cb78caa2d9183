"""What grooming paints on a face (the ``groomed`` appearance family, scene.py): eye
make-up, a beard or stubble, freckles, lipstick, all where a tracker looks.

``paint(head, scene, albedo, code)`` changes the per-vertex albedo (V, 3) linear RGB of the
painted head (``code`` (V,): its paint codes, ``Head.regions`` for the scene's look). Zones
come from the head's neutral geometry (cm, x to the subject's left, y up) and its 68
Multi-PIE landmarks, so they ride on the skin as it moves:

- eyeliner: the lid margin ``scene.liner`` cm wide, near black (where lashes and liner are);
- eyeshadow: the upper lid's skin within ``SHADOW_CM`` of the lid contour, blended toward
  ``scene.shadow_colour`` by ``scene.shadow`` (fading with distance): the lids MediaPipe
  reads a blink from change contrast;
- a beard: the front skin below the nose, blended toward the hair by ``scene.beard`` per
  vertex times a random density (stubble: thin and patchy; a full beard: dense); over the
  upper lip and chin it hides where the lips meet the skin;
- freckles: a share ``scene.freckles`` of the front skin's vertices darkened;
- lipstick: ``scene.lipstick`` in place of the lips' colour (None: the skin's own).
"""

from __future__ import annotations

import numpy as np

from faceclean.synthetic import head as H
from faceclean.synthetic.head import Head
from faceclean.synthetic.scene import Scene

SHADOW_CM = 1.0  # how far above the lid contour eyeshadow reaches
BEARD_TOP_CM = 0.3  # a beard starts this far below the nose's base (landmark 33)
BEARD_NECK_CM = 2.0  # ... and ends this far below the chin (landmark 8)
FRONT_CM = 2.0  # the front half of the head: z above this (the jaw's corners sit at 4.5)


def paint(head: Head, s: Scene, albedo: np.ndarray, code: np.ndarray) -> np.ndarray:
    """``albedo`` (V, 3) with ``s``'s grooming painted on (a copy)."""
    rng = np.random.default_rng([s.seed, 17])
    out = albedo.copy()
    v, lm = head.neutral, head.landmarks
    skin = (code == H.SKIN) & (v[:, 2] > FRONT_CM)  # (V,) the front skin, nothing painted
    if s.lipstick is not None:
        out[code == H.LIPS] = s.lipstick
    if s.shadow > 0:
        eye_y = v[lm[36:48], 1].mean()
        near = skin & (head.lid_cm < SHADOW_CM) & (v[:, 1] > eye_y)
        a = s.shadow * (1.0 - head.lid_cm[near] / SHADOW_CM)[:, None]
        out[near] = (1.0 - a) * out[near] + a * np.asarray(s.shadow_colour)
    if s.liner > 0:
        out[np.isin(code, (H.SKIN, H.LID)) & (head.lid_cm < s.liner)] = 0.02
    if s.beard > 0:
        hair = np.asarray(s.hair if s.hair is not None else s.brows)
        zone = skin & (v[:, 1] < v[lm[33], 1] - BEARD_TOP_CM)
        zone &= v[:, 1] > v[lm[8], 1] - BEARD_NECK_CM
        density = np.clip(rng.normal(s.beard, 0.15, zone.sum()), 0.0, 1.0)[:, None]
        out[zone] = (1.0 - density) * out[zone] + density * hair
    if s.freckles > 0:
        dots = skin & (rng.random(len(v)) < s.freckles)
        out[dots] *= 0.7
    return out
