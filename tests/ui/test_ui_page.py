"""The tuning page in a real headless Chromium against the real commands: ``faceclean ui``
on a shared take, and ``faceclean relay --ui`` fed by ``faceclean replay`` of one, with
a real receiver. Needs Debian's chromium and playwright (tests/headless.py)."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest
from headless import BROWSER_ARGS, CHROMIUM, browser_missing
from helpers import REPO, first_take, interrupt, reaped

from faceclean import io
from faceclean.cli import main

pytest.importorskip("websockets")
pytestmark = pytest.mark.skipif(browser_missing() is not None, reason=str(browser_missing()))
ENV = dict(os.environ, PYTHONPATH=str(REPO / "src"))
URL = re.compile(r"tuning page: (http://\S+)")


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=BROWSER_ARGS)
        yield b
        b.close()


def start(args: list[str]) -> tuple[subprocess.Popen, str]:
    """A faceclean command that serves the page, and the URL it printed."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "faceclean", *args, "--no-browser"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
    )
    for line in proc.stdout:
        found = URL.search(line)
        if found:
            return proc, found[1]
    proc.kill()
    raise AssertionError(f"no URL printed: {proc.stderr.read()[-2000:]}")


class Tab:
    """One page: console errors kept, waits frame by frame on a JS condition."""

    def __init__(self, browser, url: str) -> None:
        self.messages: list[tuple[str, str]] = []
        self.page = browser.new_page(viewport={"width": 1400, "height": 1000})
        self.page.on("console", lambda m: self.messages.append((m.type, m.text)))
        self.page.on("pageerror", lambda e: self.messages.append(("pageerror", str(e))))
        self.page.goto(url)
        self.until("window.faceclean && window.faceclean.ready")

    def until(self, condition: str) -> None:
        self.page.evaluate(
            "() => new Promise((done) => { const check = () => (" + condition + ")"
            " ? done(true) : requestAnimationFrame(check); check(); })"
        )

    def js(self, expression: str):
        return self.page.evaluate(expression)

    def slide(self, key: str, fraction: float) -> int:
        """Click the slider of ``key`` at ``fraction`` of its width, as a user does; the
        sequence number of the settings message it sent."""
        box = self.page.locator(f"#fc-{key}").bounding_box()
        before = self.js("window.faceclean.setSeq")
        self.page.mouse.click(box["x"] + fraction * box["width"], box["y"] + box["height"] / 2)
        self.until(f"window.faceclean.setSeq > {before}")
        return self.js("window.faceclean.setSeq")

    def settled(self, seq: int) -> None:
        """Until the state and the whole cleaned take answer message ``seq``."""
        self.until(
            f"window.faceclean.state.seq >= {seq} && window.faceclean.fullSeq >= {seq}"
            f" || window.faceclean.errors.length"
        )
        assert self.js("window.faceclean.errors") == []

    def note_after(self, button: str, text: str) -> None:
        n = self.js("window.faceclean.notes.length")
        self.page.click(button)
        self.until(f"window.faceclean.notes.length > {n} || window.faceclean.errors.length")
        assert self.js("window.faceclean.errors") == []
        assert text in self.js("window.faceclean.notes.at(-1)")

    def errors(self) -> list[tuple[str, str]]:
        return [m for m in self.messages if m[0] in ("error", "pageerror")]


def _cleaned(tab: Tab, n: int) -> np.ndarray:
    return np.array(tab.js("Array.from(window.faceclean.cleaned)"), np.float64).reshape(n, 52)


def test_offline_page_tunes_calibrates_and_saves_what_clean_reproduces(browser, tmp_path):
    take = first_take("jmtechart")
    anim = io.load(take)
    proc, url = start(["ui", str(take), "--method", "one-euro"])
    with reaped(proc):
        tab = Tab(browser, url)
        tab.settled(0)
        assert tab.js("window.faceclean.mode") == "offline"
        before = _cleaned(tab, anim.n_frames)
        tab.page.select_option("#fc-scope", "eyes")
        tab.settled(tab.slide("min_cutoff", 0.05))  # eyes: heavy smoothing
        tab.page.select_option("#fc-scope", "jawOpen")
        tab.settled(tab.slide("gain", 0.4))  # jawOpen.gain=1.6
        items = tab.js("window.faceclean.state.items")
        assert [i.split("=")[0] for i in items] == ["eyes.min_cutoff", "jawOpen.gain"]
        tab.page.fill("#fc-hold", "1")
        n = tab.js("window.faceclean.sentSeq")
        tab.page.click("#fc-calibrate")
        tab.settled(n + 1)
        facts = tab.js("window.faceclean.state.calibration")
        assert facts["take"] == take.name and facts["frames"] == anim.valid.sum()
        page = _cleaned(tab, anim.n_frames)
        tab.page.fill("#fc-path", str(tmp_path / "preset.json"))
        tab.note_after("#fc-save-preset", "saved preset")
        tab.page.fill("#fc-path", str(tmp_path / "levels.json"))
        tab.note_after("#fc-save-levels", "saved levels")
        assert tab.errors() == []
        tab.page.screenshot(path=str(tmp_path / "offline.png"))
        if os.environ.get("FACECLEAN_SCREENSHOTS"):  # docs/ui-offline.png
            tab.page.screenshot(path=os.environ["FACECLEAN_SCREENSHOTS"] + "/ui-offline.png")
        tab.page.close()
        interrupt(proc)
    assert np.nanmax(np.abs(page - before)) > 0.05  # the page's changes show
    files = ["--preset", str(tmp_path / "preset.json")]
    files += ["--calibration", str(tmp_path / "levels.json")]
    assert main(["clean", str(take), "-o", str(tmp_path / "out.csv"), *files]) == 0
    out, present = io.load(tmp_path / "out.csv").arkit()
    assert present.sum() == anim.arkit()[1].sum()
    gap = np.abs(out[:, present] - page[:, present])
    assert np.nanmax(gap) < 1e-6  # the files give what the page showed
    assert np.array_equal(np.isnan(out[:, present]), np.isnan(page[:, present]))
