"""A real headless Chromium for the tests that open a report (tests/report/, test_install).

Needs Debian's ``chromium`` (/usr/bin/chromium, installed by .ci/run) and the
``playwright`` Python package (dev extra); WebGL runs on SwiftShader (software GL).
"""

from __future__ import annotations

import io as pyio
import json
import re
from pathlib import Path

import numpy as np

from faceclean.errors import FacecleanError
from faceclean.report import build

CHROMIUM = Path("/usr/bin/chromium")
BROWSER_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-default-apps",
    "--no-first-run",
]


def browser_missing() -> str | None:
    if not CHROMIUM.exists():
        return "no /usr/bin/chromium (Debian package 'chromium'; .ci/run installs it)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "python package 'playwright' is not installed (dev extra)"
    try:
        build.node_modules()
    except FacecleanError as e:
        return str(e)
    return None


class Page:
    """A report opened in Chromium, with every console message and request recorded."""

    def __init__(self, browser, path: Path) -> None:
        self.messages: list[tuple[str, str]] = []
        self.requests: list[str] = []
        self.blocked: list[str] = []
        self.page = browser.new_page(viewport={"width": 1100, "height": 900})
        self.page.on("console", lambda m: self.messages.append((m.type, m.text)))
        self.page.on("pageerror", lambda e: self.messages.append(("pageerror", str(e))))
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.route(re.compile(r"^(?!file:|data:)"), self._block)
        self.page.goto(path.as_uri())
        self.until("window.faceclean && window.faceclean.ready")

    def until(self, condition: str) -> None:
        until(self.page, condition)

    def _block(self, route) -> None:
        self.blocked.append(route.request.url)
        route.abort()

    def errors(self) -> list[tuple[str, str]]:
        return [m for m in self.messages if m[0] in ("error", "pageerror")]

    def view(self, t: float | None = None) -> np.ndarray:
        """(H, W, 3) screenshot of the 3D view (at time t when given), floats in [0, 1]."""
        from matplotlib.image import imread

        if t is not None:
            self.page.evaluate(f"window.faceclean.seek({t})")
        png = self.page.locator("#fc-canvas").screenshot()
        return imread(pyio.BytesIO(png))[..., :3]


def until(page, condition: str, seconds: float = 120.0) -> None:
    """Wait, frame by frame, until the JS condition holds (wait_for_function would need
    eval, which the pages' Content-Security-Policy forbids); past ``seconds`` the test
    fails naming the condition, never hangs (a live recording is 37 s)."""
    give_up = f"fail(new Error('still false: ' + {json.dumps(condition)}))"
    page.evaluate(
        "([s]) => new Promise((done, fail) => { const end = performance.now() + 1000 * s;"
        f" const check = () => ({condition}) ? done(true) : performance.now() > end ?"
        f" {give_up} : requestAnimationFrame(check); check(); }})",
        [seconds],
    )
