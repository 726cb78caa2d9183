"""Set-up leaves the report working: ``make demo`` installs three.js, and a wheel built
from the repository renders the report with no node_modules anywhere.

The build hook (setup.py) copies the pinned three.js from node_modules/three into the
wheel. The test builds the wheel from a copy of the build inputs (so nothing is written
into the repository), installs it into a fresh venv in tmp, and runs that venv's
``faceclean`` from an empty folder with only the shared venv's site-packages (numpy,
scipy, ...) on PYTHONPATH: the repository's src/ and node_modules/ are out of reach.
"""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from headless import BROWSER_ARGS, CHROMIUM, Page, browser_missing
from helpers import REPO

THREE = REPO / "node_modules" / "three"
INPUTS = ("pyproject.toml", "setup.py", "README.md", "MANIFEST.in", "package.json")
INPUTS += ("package-lock.json", "LICENSE")

pytestmark = pytest.mark.skipif(
    not (THREE / "package.json").is_file(),
    reason="node_modules/three is absent: run `npm ci` (the wheel build copies it)",
)


def _run(args: list[str], cwd: Path, env: dict[str, str]) -> str:
    done = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{args[:3]}: {done.stdout[-1500:]}{done.stderr[-1500:]}"
    return done.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """(the fresh venv, the environment to run it in)."""
    tmp = tmp_path_factory.mktemp("wheel")
    tree = tmp / "tree"
    tree.mkdir()
    for name in INPUTS:
        shutil.copy2(REPO / name, tree / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "vendor")
    shutil.copytree(REPO / "src", tree / "src", ignore=ignore)
    build_env = dict(os.environ, FACECLEAN_NODE_MODULES=str(REPO / "node_modules"))
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check"]
    _run([*pip, "wheel", ".", "--no-deps", "--no-build-isolation", "-w", str(tmp / "dist")],
         tree, build_env)  # fmt: skip
    [wheel] = (tmp / "dist").glob("faceclean-*.whl")
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp, build_env)
    _run([*pip, "--python", str(venv / "bin" / "python"), "install", "--no-deps", "--no-index",
          str(wheel)], tmp, build_env)  # fmt: skip
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "FACECLEAN_"))}
    env["PYTHONPATH"] = sysconfig.get_paths()["purelib"]  # the dependencies only
    return venv, env


@pytest.fixture(scope="module")
def report(installed, tmp_path_factory) -> Path:
    venv, env = installed
    run = tmp_path_factory.mktemp("run")  # an empty folder: no node_modules here or above
    faceclean = str(venv / "bin" / "faceclean")
    _run([faceclean, "synth", "-o", "take.csv", "--seconds", "3", "--format", "livelink"],
         run, env)  # fmt: skip
    _run([faceclean, "report", "take.csv", "-o", "report.html"], run, env)
    return run / "report.html"


def test_the_installed_package_is_the_wheel_with_its_own_three(installed, tmp_path):
    venv, env = installed
    code = (
        "import faceclean, faceclean.report.build as b; "
        "print(faceclean.__file__); print(b.node_modules())"
    )
    where, three = _run([str(venv / "bin" / "python"), "-c", code], tmp_path, env).split()
    site = venv / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"
    assert Path(where) == site / "faceclean" / "__init__.py"
    assert Path(three) == site / "faceclean" / "report" / "vendor"
    for name in ("build/three.module.js", "build/three.core.js"):
        assert (Path(three) / "three" / name).read_bytes() == (THREE / name).read_bytes()
    assert not list(REPO.glob("src/faceclean/report/vendor"))  # never copied into src/


def test_the_wheel_carries_every_file_the_tuning_page_serves(installed, tmp_path):
    venv, env = installed
    code = (
        "import faceclean.ui.server as s; [print(u, p, p.is_file()) for u, p in s.files().items()]"
    )
    rows = [r.split() for r in _run([str(venv / "bin" / "python"), "-c", code], tmp_path, env)
            .splitlines()]  # fmt: skip
    site = venv / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"
    from faceclean.ui import server

    assert len(rows) == len(server.files()) >= 8 and all(ok == "True" for _, _, ok in rows)
    assert all(Path(p).is_relative_to(site / "faceclean") for _, p, _ in rows)  # no repo file


def test_the_report_from_the_wheel_embeds_the_pinned_three(report):
    html = report.read_text(encoding="utf-8")
    imports = json.loads(re.search(r'<script type="importmap">(.*?)</script>', html, re.S)[1])
    core = imports["imports"]["three/core"].split(",", 1)[1]
    assert base64.b64decode(core) == (THREE / "build" / "three.core.js").read_bytes()
    pinned = json.loads((REPO / "package-lock.json").read_text())["packages"]
    assert f"three.js {pinned['node_modules/three']['version']}" in html


@pytest.mark.skipif(browser_missing() is not None, reason=str(browser_missing()))
def test_the_report_from_the_wheel_plays_in_chromium(report):
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=BROWSER_ARGS)
        page = Page(browser, report)
        a, b = page.view(0.5), page.view(2.0)
        assert page.errors() == [] and page.blocked == []
        assert a.std() > 0.05 and np.abs(a - b).mean() > 0.001  # a face, and it moves
        browser.close()


def test_make_demo_installs_three_js_too(tmp_path):
    """``make -n demo`` in a copy with the venv set up but no node_modules: the plan
    runs ``npm ci`` (the demo target depends on the node stamp)."""
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    for name in ("Makefile", "pyproject.toml", "package.json", "package-lock.json"):
        shutil.copy2(REPO / name, tmp_path / name)
    (tmp_path / ".venv" / "bin").mkdir(parents=True)
    stamp = tmp_path / ".venv" / ".installed"
    stamp.touch()
    os.utime(stamp, (2e9, 2e9))  # newer than pyproject.toml: the venv is up to date
    plan = _run(["make", "-n", "demo"], tmp_path, dict(os.environ))
    assert "npm ci" in plan and "faceclean demo" in plan
    assert plan.index("npm ci") < plan.index("faceclean demo")
    assert "pip install" not in plan
