"""``faceclean track --camera N --send URL --ui``: the live page on the camera's loop.

The page of ``relay --ui`` (ui/live.py: the same controls, faces, curves, calibrations;
the loop, trackers/live.py, takes a new cleaner between two frames as the relay does),
with the camera's image beside the two faces and the camera's counters in the status
line: frames captured, **dropped** (replaced before the loop took them, the camera's own
count, as the relay counts stale frames), tracked, without a face, sent, and what the
loop adds to MediaPipe (p50, p99).

The image never slows the loop: the loop hands each frame to ``image``, which keeps a
reference and returns. A thread of the page takes the newest one at most ``IMAGE_HZ``
times a second while a page is open, scales it to ``IMAGE_WIDTH`` pixels wide and sends
it as a JPEG (``QUALITY``) over the page's channel, one binary message: uint32
little-endian header length, the JSON header ``{"kind": "image", "t": s, "width",
"height", "bytes"}``, spaces to a multiple of 4 bytes, then the JPEG's bytes. A frame the
thread had no time for is not sent; the next one is.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from faceclean.ui.live import Live, Tap
from faceclean.ui.tuning import Tuning

IMAGE_HZ = 5.0  # images a second to a page, at most
IMAGE_WIDTH = 320  # px, the image's width on the channel (the camera's own if smaller)
QUALITY = 70  # JPEG quality, 0-100


class CameraPage(Live):
    """The page on the camera loop ``loop`` (trackers/live.Live) reading ``camera``."""

    def __init__(self, tuning: Tuning, loop: Any, camera: Any, tap: Tap, describe: str,
                 nice: int = 0, say: Callable[[str], None] | None = None,
                 script: Any = None) -> None:  # fmt: skip
        super().__init__(tuning, loop, tap, describe, nice, say, script)
        self.camera = camera
        self.newest: tuple[np.ndarray, float] | None = None  # (H, W, 3) RGB, capture s
        self.images = 0  # images sent
        self._images = threading.Thread(target=self._send_images, name="faceclean-ui-camera",
                                        daemon=True)  # fmt: skip

    def image(self, rgb: np.ndarray, t: float) -> None:
        """The loop's frame (``on_image``): kept, nothing more."""
        self.newest = (rgb, t)

    def start(self) -> CameraPage:
        super().start()
        self._images.start()
        return self

    def stop(self) -> None:
        super().stop()
        if self._images.is_alive():
            self._images.join(5.0)

    def hello(self) -> dict[str, Any]:
        return {**super().hello(), "camera": self.what}

    def _send_images(self) -> None:
        sent = None
        while not self._stop.wait(1.0 / IMAGE_HZ):
            newest = self.newest
            if not self.clients or newest is None or newest is sent:
                continue
            sent = newest
            self.broadcast_bytes(jpeg_message(*newest))
            self.images += 1

    def _stats(self, frames: int, seconds: float) -> dict[str, Any]:
        s = self.relay.stats

        def ms(samples: list[int], q: float) -> float | None:
            return float(np.percentile(samples, q)) / 1e6 if samples else None

        track, added = list(s.track_ns), list(s.added_ns)
        return {
            "camera": self.what,
            "rate": frames / seconds if seconds > 0 else 0.0,
            "captured": self.camera.captured,
            "dropped": self.camera.dropped,
            "tracked": s.tracked,
            "lost": s.lost,
            "sent": s.sent,
            "mediapipe_p50": ms(track, 50),
            "p50": ms(added, 50),
            "p99": ms(added, 99),
            "images": self.images,
        }


def jpeg_message(rgb: np.ndarray, t: float) -> bytes:
    """One image message (module docstring): ``rgb`` (H, W, 3) uint8 scaled to
    IMAGE_WIDTH px wide at most, as a JPEG."""
    import cv2  # the camera's own library (the extra ``track``)

    h, w = rgb.shape[:2]
    if w > IMAGE_WIDTH:
        size = (IMAGE_WIDTH, max(1, round(h * IMAGE_WIDTH / w)))
        rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, QUALITY])  # fmt: skip
    body = data.tobytes() if ok else b""
    head = json.dumps({"kind": "image", "t": round(float(t), 5), "width": int(rgb.shape[1]),
                       "height": int(rgb.shape[0]), "bytes": len(body)}).encode()  # fmt: skip
    head += b" " * (-(len(head) + 4) % 4)
    return len(head).to_bytes(4, "little") + head + body
