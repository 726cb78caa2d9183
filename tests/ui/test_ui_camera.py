"""``faceclean track --camera FILE --send URL --ui``: the camera's image on the tuning page
beside the two faces, in a real headless Chromium. No camera exists here: a video of
rendered faces stands in for one through the same capture class (tests/trackers), a real
Live Link receiver on loopback gets what the loop sends. Needs Debian's chromium,
playwright, MediaPipe's model, the renderer and the shared head mesh."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from headless import BROWSER_ARGS, CHROMIUM, browser_missing
from helpers import interrupt, reaped
from test_ui_page import Receiver, Tab, start

from faceclean.channels import ARKIT52

pytest.importorskip("websockets")
pytestmark = pytest.mark.skipif(browser_missing() is not None, reason=str(browser_missing()))
JAW = ARKIT52.index("jawOpen")
REPEAT = 60  # the rendered second, 60 times: a stand-in camera that outlasts the test (13-22 s)
_spec = importlib.util.spec_from_file_location(
    "tracker_videos", Path(__file__).parents[1] / "trackers" / "conftest.py"
)
videos = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(videos)  # the trackers' rendered faces and video writer
rendered = videos.rendered  # the session fixture: (30, H, W, 3) rendered faces


@pytest.fixture(scope="module")
def camera_video(rendered, tmp_path_factory) -> str:
    frames = np.concatenate([rendered] * REPEAT)
    return videos.write_video(tmp_path_factory.mktemp("camera") / "camera.mp4", frames, 30)


@pytest.mark.slow
def test_track_ui_shows_the_camera_beside_the_faces_and_swaps_the_cleaner(camera_video,
                                                                          tmp_path):  # fmt: skip
    from playwright.sync_api import sync_playwright
    from test_guided import SHORT

    receiver = Receiver()
    script = tmp_path / "short.json"  # a studio's own guided script (--script)
    script.write_text(json.dumps(SHORT))
    track, url = start(["track", "--camera", camera_video, "--send",
                        f"livelink://127.0.0.1:{receiver.port}", "--method", "one-euro", "--ui",
                        "--ui-nice", "0",  # a loaded machine: the test's browser keeps its weight
                        "--script", str(script)], stderr=subprocess.DEVNULL)  # fmt: skip
    with reaped(track), sync_playwright() as p:
        # a browser of its own (the page may lower its browser's priority)
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=BROWSER_ARGS)
        tab = Tab(browser, url)
        tab.until(
            "window.faceclean.images > 1 && window.faceclean.stats && window.faceclean.frames > 0"
        )
        assert tab.page.is_visible("#fc-camera") and tab.js("window.faceclean.imageSize")[0] == 320
        size = tab.js("[document.querySelector('#fc-camera').width, "
                      "document.querySelector('#fc-camera').height]")  # fmt: skip
        assert size == tab.js("window.faceclean.imageSize")  # drawn at the size it came
        box = "(s) => document.querySelector(s).getBoundingClientRect().toJSON()"
        camera, faces = tab.js(f"['#fc-camera-box', '.stage'].map({box})")
        assert camera["right"] <= faces["left"]  # beside the faces, to their left
        assert camera["width"] > 100 and camera["top"] == faces["top"]
        status = tab.page.inner_text("#fc-status")
        found = re.search(r"dropped (\d+)", status)
        assert found, (status, track.poll())
        shown = int(found[1])  # the camera's count, shown
        assert status.startswith(f"camera {camera_video}") and "MediaPipe p50" in status
        assert "faceclean tuning: camera" in tab.page.inner_text("#fc-title")
        if os.environ.get("FACECLEAN_SCREENSHOTS"):  # docs/ui-camera.png
            tab.page.screenshot(path=os.environ["FACECLEAN_SCREENSHOTS"] + "/ui-camera.png")

        # a change of the cleaner is taken between two frames of the camera loop
        while not any(v[JAW] > 0.05 for _, v in receiver.frames):
            assert track.poll() is None, "the stand-in camera ended first"
            receiver.arrived.clear()
            receiver.arrived.wait(1.0)
        tab.page.fill("#fc-items", "jawOpen.gain=0")
        n = tab.js("window.faceclean.sentSeq")
        tab.page.click("#fc-apply")
        tab.until(f"window.faceclean.state.seq >= {n + 1} || window.faceclean.errors.length")
        assert tab.js("window.faceclean.errors") == []
        after = len(receiver.frames) + 2  # a frame in flight may carry the old cleaner
        while len(receiver.frames) < after + 30:
            assert track.poll() is None, "the stand-in camera ended first"
            receiver.arrived.clear()
            receiver.arrived.wait(1.0)
        jaw = np.array([v[JAW] for _, v in receiver.frames[after : after + 30]])

        # the guided calibration records from the camera loop too (then stopped here: the
        # stand-in face does not perform the script), prompting the studio's own script
        rows = tab.js("document.querySelectorAll('#fc-guided-prompts tbody tr').length")
        assert rows == len(SHORT["prompts"])
        tab.page.click("#fc-guided-start")
        summary = "document.querySelector('#fc-guided-summary').textContent"
        tab.until(f"/recording: [1-9]/.test({summary}) || window.faceclean.errors.length")
        tab.page.click("#fc-guided-stop")
        tab.until("window.faceclean.guidedPhase === 'stopped' || window.faceclean.errors.length")
        assert tab.js(summary) == "stopped: stopped from the page"
        assert tab.errors() == []
        tab.page.close()
        browser.close()
        out, err = interrupt(track)
    receiver.close()
    assert np.abs(jaw).max() < 1e-6, jaw
    dropped = int(re.search(r"stopped: camera \d+ dropped (\d+)", out)[1])
    assert dropped >= shown
