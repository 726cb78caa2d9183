"""The report's 3D faces turn their heads: the payload carries each version's head angles
and a real headless Chromium shows the faces turned by them (input raw, output cleaned)."""

from __future__ import annotations

import numpy as np
import pytest
from headless import BROWSER_ARGS, CHROMIUM, Page, browser_missing
from scipy.spatial.transform import Rotation
from test_report import _data

from faceclean.animation import Animation
from faceclean.channels import INDEX, POSE
from faceclean.cli import main
from faceclean.evaluation import comparison
from faceclean.io import save
from faceclean.pose import gltf_quaternion
from faceclean.report import payload

needs_browser = pytest.mark.skipif(browser_missing() is not None, reason=str(browser_missing()))
FPS, SECONDS = 60.0, 3.0


def _take() -> Animation:
    """The jaw moves; the head turns 30 degrees at 1.5 s and back, with tracker jitter."""
    t = np.arange(int(FPS * SECONDS)) / FPS
    v = np.zeros((len(t), 52))
    v[:, INDEX["jawOpen"]] = 0.3
    pose = np.zeros((len(t), 9))
    pose[:, 0] = np.radians(30) * np.sin(np.pi * t / SECONDS)  # yaw
    pose[:, 1] = np.radians(5)  # pitch
    pose[:, :3] += np.random.default_rng(3).normal(0, 0.004, (len(t), 3))
    pose[:, 3:] = 0.05
    return Animation(t, v, tuple(n for n in INDEX), {"pose": pose, "pose_names": POSE})


def test_the_payload_carries_each_versions_head():
    comp = comparison.compare(_take(), None, ["one-euro"])
    data = payload.animation(comp)
    raw, cleaned = (np.array(s["head"]) for s in data["series"])  # (3, N) rad each
    assert raw.shape == cleaned.shape == (3, len(data["times"]))
    np.testing.assert_allclose(raw, np.round(_take().meta["pose"][:, :3].T, 4))

    def jitter(a):
        return np.mean(np.diff(a, 2, axis=1) ** 2)

    assert jitter(cleaned) < 0.5 * jitter(raw)  # the output's head is the cleaned one
    plain = comparison.compare(Animation(np.arange(3) / 60, np.zeros((3, 1)), ["jawOpen"]))
    assert all(s["head"] is None for s in payload.animation(plain)["series"])


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    from playwright.sync_api import sync_playwright

    folder = tmp_path_factory.mktemp("head")
    save(_take(), folder / "take.csv", fmt="livelink")
    out = folder / "r.html"
    assert main(["report", str(folder / "take.csv"), "--method", "one-euro", "-o", str(out)]) == 0
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=BROWSER_ARGS)
        page = Page(browser, out)
        page.data = _data(out.read_text())
        yield page
        browser.close()


@needs_browser
def test_the_faces_turn_their_heads(page):
    still = page.view(0.0)
    at0 = np.array(page.page.evaluate("window.faceclean.heads"))  # (2, 4)
    turned = page.view(1.5)
    at15 = np.array(page.page.evaluate("window.faceclean.heads"))
    assert page.errors() == []
    assert np.abs(turned - still).mean() > 0.003  # the picture changes with the head
    raw, cleaned = (np.array(s["head"]) for s in page.data["series"])
    k = int(np.argmin(np.abs(np.array(page.data["times"]) - 1.5)))
    for q, ypr in zip(at15, (raw[:, k], cleaned[:, k]), strict=True):  # each face its own
        want = gltf_quaternion(ypr)
        assert abs(np.dot(q, want)) > 1 - 1e-6
    yaw = [Rotation.from_quat(q).as_euler("YXZ")[0] for q in at15]  # glTF: -yaw about Y
    assert all(np.degrees(-y) > 25 for y in yaw)
    assert all(abs(np.degrees(-Rotation.from_quat(q).as_euler("YXZ")[0])) < 2 for q in at0)
