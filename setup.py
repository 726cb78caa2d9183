"""Build hook: a built wheel carries the pinned three.js its HTML report inlines.

Everything else about the package is in pyproject.toml. ``build_py`` copies, from the npm
package (node_modules/three, installed by ``npm ci`` from package-lock.json, which this
runs when it is absent), the files the report needs into the built package at
``faceclean/report/vendor/three/``: build/three.module.js, build/three.core.js,
package.json (its version) and LICENSE. Never into src/ and never into git; an editable
install reads node_modules/ directly instead.
"""

import json
import os
import shutil
import subprocess
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
FILES = ("build/three.module.js", "build/three.core.js", "package.json", "LICENSE")


def _pinned() -> str:
    lock = json.loads((ROOT / "package-lock.json").read_text())
    return lock["packages"]["node_modules/three"]["version"]


def _three() -> Path:
    """node_modules/three at the pinned version ($FACECLEAN_NODE_MODULES, else ours)."""
    folder = Path(os.environ.get("FACECLEAN_NODE_MODULES") or ROOT / "node_modules")
    three = folder / "three"
    if not (three / "package.json").is_file() and folder == ROOT / "node_modules":
        if shutil.which("npm") is None:
            raise SystemExit(
                "building faceclean needs three.js from npm: install npm, or run npm ci"
            )
        subprocess.run(["npm", "ci", "--omit=dev", "--no-audit", "--no-fund"], cwd=ROOT, check=True)
    if not (three / "package.json").is_file():
        raise SystemExit(f"no three.js in {folder}: run npm ci")
    version, pinned = json.loads((three / "package.json").read_text())["version"], _pinned()
    if version != pinned:
        raise SystemExit(f"{three} is three {version}, package-lock.json pins {pinned}: npm ci")
    return three


class BuildPy(build_py):
    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        three = _three()
        target = Path(self.build_lib) / "faceclean" / "report" / "vendor" / "three"
        for name in FILES:
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(three / name, target / name)


setup(cmdclass={"build_py": BuildPy})
