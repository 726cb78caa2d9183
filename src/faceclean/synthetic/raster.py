"""A z-buffered triangle rasteriser with Gouraud colours (numba, one core).

Screen space: x right, y down, in pixels, pixel centres at +0.5; ``depth`` grows away from
the camera. Both windings are drawn (the ICT mesh is not consistently wound inside the
mouth and the eyes); the z-buffer decides what is seen.
"""

from __future__ import annotations

import numpy as np

from faceclean.errors import FacecleanError

try:
    import numba
except ImportError:  # pragma: no cover - the pairs extra brings numba
    numba = None


def rasterise(
    xy: np.ndarray, depth: np.ndarray, colour: np.ndarray, triangles: np.ndarray, size: int
) -> tuple[np.ndarray, np.ndarray]:
    """Draw triangles (T, 3) over vertices ``xy`` (V, 2) px, ``depth`` (V,), ``colour`` (V, C)
    (any C attributes, interpolated: RGB, or a texture's coordinates and shading).

    Returns (image (size, size, C) float32, coverage (size, size) bool).
    """
    if numba is None:
        raise FacecleanError("the renderer needs numba: pip install 'faceclean[pairs]'")
    image = np.zeros((size, size, colour.shape[1]), np.float32)
    zbuf = np.full((size, size), np.inf, np.float32)
    _draw(
        xy.astype(np.float32),
        depth.astype(np.float32),
        colour.astype(np.float32),
        triangles,
        image,
        zbuf,
    )
    return image, np.isfinite(zbuf)


def _draw_py(xy, depth, colour, tris, image, zbuf):  # pragma: no cover - compiled below
    h, w = zbuf.shape
    for t in range(tris.shape[0]):
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        ax, ay, bx, by, cx, cy = xy[a, 0], xy[a, 1], xy[b, 0], xy[b, 1], xy[c, 0], xy[c, 1]
        area = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if abs(area) < 1e-8:
            continue
        x0 = max(int(np.floor(min(ax, bx, cx))), 0)
        x1 = min(int(np.ceil(max(ax, bx, cx))), w - 1)
        y0 = max(int(np.floor(min(ay, by, cy))), 0)
        y1 = min(int(np.ceil(max(ay, by, cy))), h - 1)
        inv = 1.0 / area
        for y in range(y0, y1 + 1):
            py = y + 0.5
            for x in range(x0, x1 + 1):
                px = x + 0.5
                # barycentric weights from the edge functions
                wa = ((bx - px) * (cy - py) - (cx - px) * (by - py)) * inv
                wb = ((cx - px) * (ay - py) - (ax - px) * (cy - py)) * inv
                wc = 1.0 - wa - wb
                if wa < 0 or wb < 0 or wc < 0:
                    continue
                z = wa * depth[a] + wb * depth[b] + wc * depth[c]
                if z < zbuf[y, x]:
                    zbuf[y, x] = z
                    for k in range(image.shape[2]):
                        image[y, x, k] = wa * colour[a, k] + wb * colour[b, k] + wc * colour[c, k]


_draw = numba.njit(cache=True, nogil=True)(_draw_py) if numba is not None else _draw_py
