"""The HTML report: self-contained, compact data, and a real headless Chromium playing it.

Browser tests need Debian's ``chromium`` (/usr/bin/chromium, installed by .ci/run) and
the ``playwright`` Python package (dev extra); WebGL runs on SwiftShader (software GL).
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from headless import Page, browser_missing

from faceclean import report
from faceclean.animation import Animation
from faceclean.channels import INDEX
from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.evaluation import comparison
from faceclean.face import mesh as facemesh
from faceclean.io import save
from faceclean.report import build, payload
from faceclean.settings import data_dir

MESHES = data_dir() / "meshes" if data_dir() is not None else None


needs_browser = pytest.mark.skipif(browser_missing() is not None, reason=str(browser_missing()))


def _clip(seconds: float = 4.0, fps: float = 60.0) -> tuple[Animation, Animation]:
    """(noisy, truth at 30 fps): the jaw opens and closes, the eyes blink, jitter on top."""
    t = np.arange(int(seconds * fps)) / fps
    clean = np.zeros((len(t), 52))
    clean[:, INDEX["jawOpen"]] = 0.5 - 0.5 * np.cos(2 * np.pi * t / seconds)
    blink = np.exp(-(((t - 1.0) / 0.07) ** 2)) + np.exp(-(((t - 3.0) / 0.07) ** 2))
    clean[:, INDEX["eyeBlinkLeft"]] = clean[:, INDEX["eyeBlinkRight"]] = blink
    clean[:, INDEX["mouthSmileLeft"]] = clean[:, INDEX["mouthSmileRight"]] = 0.4 * t / seconds
    noisy = clean + np.random.default_rng(1).normal(0, 0.02, clean.shape)
    noisy[len(t) // 2 - 20] = np.nan  # one tracking-loss frame
    truth = Animation.from_arkit(t[::2], clean[::2])
    return Animation.from_arkit(t, noisy.clip(0, 1)), truth


def _data(html: str) -> dict:
    m = re.search(r'<script type="application/json" id="fc-data">(.*?)</script>', html, re.S)
    return json.loads(m.group(1))


def test_payload_is_compact_and_decimates_long_clips():
    noisy, truth = _clip()
    comp = comparison.compare(noisy, truth, ["one-euro", "ema"])
    data = payload.animation(comp)
    assert [s["kind"] for s in data["series"]] == ["input", "truth", "output", "output"]
    assert data["face"] == [0, 2] and data["stride"] == 1
    jaw = data["series"][0]["values"][INDEX["jawOpen"]]
    assert all(v is None or isinstance(v, int) for v in jaw) and jaw[100] is None  # frame 100
    assert [g["title"] for g in data["groups"]] == [
        "eyes",
        "brows",
        "jaw",
        "mouth",
        "cheeks and nose",
    ]
    eyes = data["groups"][0]["channels"]
    assert {data["channels"][j] for j in eyes[:2]} == {"eyeBlinkLeft", "eyeBlinkRight"}
    # A 2-hour clip keeps every k-th frame, within the budget.
    assert payload.stride(432_000, 52 * 4) * payload.MAX_VALUES >= 432_000 * 52 * 4
    assert payload.stride(600, 52 * 4) == 1


def test_mesh_payload_keeps_every_target():
    face = facemesh.stylised()
    m = payload.mesh(face)
    assert len(m["targets"]) == 52 and [t["ch"] for t in m["targets"]] == list(range(52))
    n = sum(t["n"] for t in m["targets"])
    assert len(m["target_delta"]) == pytest.approx(4 * n * 6 / 3, abs=4)  # base64 of int16 x3
    assert n < 0.5 * 52 * len(face.vertices)  # sparse: a shape moves a part of the face


def test_html_has_no_external_reference_and_a_strict_policy():
    noisy, truth = _clip()
    html = report.render(comparison.compare(noisy, truth, ["one-euro"]), source="take.csv")
    assert "default-src 'none'" in html and "connect-src 'none'" in html
    assert not re.search(r"<(script|link|img|iframe)[^>]+(src|href)=", html, re.I)
    imports = json.loads(re.search(r'<script type="importmap">(.*?)</script>', html, re.S)[1])
    assert all(u.startswith("data:text/javascript;base64,") for u in imports["imports"].values())
    assert "take.csv" in html and "raw input" in html and "blink closure" in html
    data = _data(html)
    assert data["mesh"]["name"] == "faceclean stylised face"


def test_without_node_modules_the_error_says_what_to_run(tmp_path, monkeypatch):
    monkeypatch.setattr(build, "REPO", tmp_path)
    monkeypatch.setattr(build, "VENDOR", tmp_path / "vendor")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("FACECLEAN_NODE_MODULES", raising=False)
    with pytest.raises(FacecleanError, match="npm ci"):
        build.node_modules()


def test_cli_refuses_bad_output_and_bad_mesh(tmp_path, capsys):
    noisy, _ = _clip(seconds=1.0)
    path = tmp_path / "noisy.csv"
    save(noisy, path, fmt="csv")
    assert main(["report", str(path), "-o", str(tmp_path / "report.txt")]) == 2
    assert main(["report", str(path), "--mesh", str(path), "-o", str(tmp_path / "r.html")]) == 2
    assert capsys.readouterr().err.count("faceclean: ") == 2
    assert not list(tmp_path.glob("*.html"))


# ---- in a real browser ------------------------------------------------------------------


@pytest.fixture(scope="module")
def opened(browser, tmp_path_factory):
    folder = tmp_path_factory.mktemp("report")
    noisy, truth = _clip()
    save(noisy, folder / "noisy.csv", fmt="livelink")
    save(truth, folder / "clean.csv", fmt="csv")
    out = folder / "report.html"
    args = [str(folder / "noisy.csv"), "--truth", str(folder / "clean.csv")]
    assert main(["report", *args, "--compare", "ema", "-o", str(out)]) == 0
    page = Page(browser, out)
    yield page
    page.page.close()


@needs_browser
def test_opens_without_console_errors_or_network(opened):
    assert opened.errors() == []
    assert opened.blocked == []
    assert opened.requests and all(u.startswith(("file:", "data:")) for u in opened.requests)


@needs_browser
def test_the_3d_view_is_not_blank(opened):
    img = opened.view(0.0)
    assert img.shape[0] > 200 and img.shape[1] > 400
    assert img.std() > 0.05  # a face on the background, not one flat colour
    left, right = img[:, : img.shape[1] // 2], img[:, img.shape[1] // 2 :]
    assert left.std() > 0.05 and right.std() > 0.05  # both faces drawn


@needs_browser
def test_playback_changes_the_picture_and_moves_the_playhead(opened):
    page = opened.page
    still = opened.view(0.0)
    head = page.locator(".playhead").first.evaluate("e => e.style.left")
    page.click("#fc-play")
    opened.until("window.faceclean.time > 1.0")  # playing advances the clock
    page.click("#fc-play")  # pause; on a loaded machine the clip may have looped past its end
    paused = page.evaluate("window.faceclean.time")
    two_frames = "() => new Promise((ok) => requestAnimationFrame(() => requestAnimationFrame(ok)))"
    page.evaluate(two_frames)
    assert page.evaluate("window.faceclean.time") == paused  # paused means the clock stands
    moved = opened.view(2.0)  # mid-clip: the jaw is wide open
    assert np.abs(moved - still).mean() > 0.003
    assert page.locator(".playhead").first.evaluate("e => e.style.left") != head
    assert page.locator("#fc-time").inner_text().startswith("2.00")
    assert page.locator(".plot canvas").count() == 52
    assert opened.errors() == []


@needs_browser
@pytest.mark.skipif(
    MESHES is None or not (MESHES / "arkit_reference_mesh.npz").is_file(),
    reason="../shared/data/meshes is absent",
)
def test_a_users_npz_mesh_plays_too(browser, tmp_path):
    noisy, _ = _clip(seconds=2.0)
    comp = comparison.compare(noisy, None, ["one-euro"])
    face = facemesh.load(MESHES / "arkit_reference_mesh.npz")
    report.write(comp, tmp_path / "r.html", face)
    page = Page(browser, tmp_path / "r.html")
    a, b = page.view(0.0), page.view(1.0)
    assert page.errors() == [] and a.std() > 0.03 and np.abs(a - b).mean() > 0.001
    assert "without a truth" in page.page.content()
    page.page.close()


@pytest.mark.parametrize("truth", ["later", "all missing", "one frame"])
def test_a_truth_with_nothing_to_score_against_is_one_line_for_report_and_plot(
    tmp_path, capsys, truth
):
    # a truth 1000 s later or all missing: report ended on an internal error, plot wrote
    # a plot with no truth and exit 0
    noisy, clean = _clip()
    save(noisy, tmp_path / "noisy.csv", fmt="csv")
    if truth == "later":
        clean = Animation(clean.times + 1000.0, clean.values, clean.names)
    elif truth == "all missing":
        clean = clean.with_values(np.full_like(clean.values, np.nan))
    else:
        clean = Animation(clean.times[:1], clean.values[:1], clean.names)
    save(clean, tmp_path / "truth.csv", fmt="csv")
    said = {"later": "no value within the input's times", "all missing": "the truth has",
            "one frame": "fewer than 2 frames with values"}[truth]  # fmt: skip
    for cmd, out in (("report", "r.html"), ("plot", "p.png")):
        argv = [cmd, str(tmp_path / "noisy.csv"), "--truth", str(tmp_path / "truth.csv")]
        assert main([*argv, "--method", "ema", "-o", str(tmp_path / out)]) == 2
        err = capsys.readouterr().err
        assert said in err and "internal error" not in err and len(err.splitlines()) == 1
        assert not (tmp_path / out).exists()
