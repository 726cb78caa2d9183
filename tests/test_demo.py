"""``faceclean demo``: both example takes end to end, real files, two explained tables.

Nothing here pins a cleaner's figures: the shipped models are refitted now and then. What
is checked is that every row is computed, finite and written, and that what the demo says
about the default still holds.
"""

from __future__ import annotations

import subprocess
import sys
import tomllib
from fnmatch import fnmatch
from pathlib import Path

import numpy as np

from faceclean import io
from faceclean.cli import demo, main
from faceclean.datasets import paired
from faceclean.evaluation import metrics

PNG = b"\x89PNG\r\n\x1a\n"
REPO = Path(__file__).resolve().parents[1]
IPHONE_ROWS = ("raw input", "default", "one-euro (tuned)")
MEDIAPIPE_ROWS = ("raw MediaPipe", "--tracker mediapipe", "one-euro (tuned)")


def _tables(said: str) -> list[dict[str, list[float]]]:
    """Each printed table as {row label: its numbers}, in order."""
    tables: list[dict[str, list[float]]] = []
    for line in said.splitlines():
        if line.startswith(" " * demo.LABEL) and "MSE x raw" in line:
            tables.append({})
        elif tables and line[: demo.LABEL].strip() and not line.startswith(" "):
            label, cells = line[: demo.LABEL].strip(), line[demo.LABEL :].split()
            try:
                tables[-1][label] = [float(c) for c in cells]
            except ValueError:
                continue  # the legend after the tables
    return tables


def test_demo_cleans_both_takes_and_explains_its_columns(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--seconds", "6", "--seed", "3"]) == 0
    said = capsys.readouterr().out

    # (a) the iPhone-like take: a Live Link Face take in, the same format out
    a = tmp_path / "iphone"
    noisy, cleaned = io.load(a / "noisy.csv"), io.load(a / "cleaned.csv")
    truth = io.load(a / "truth.csv")
    assert noisy.meta["format"] == cleaned.meta["format"] == "livelink"
    assert np.array_equal(noisy.times, cleaned.times)
    raw, got = metrics.summary(noisy, truth), metrics.summary(cleaned, truth)
    assert got["jitter_ratio"] < raw["jitter_ratio"]  # the cleaner removed jitter

    # (b) the shipped MediaPipe pair: the cleaner it names changed the take
    b = tmp_path / "mediapipe"
    tracked, mp = io.load(b / "tracked.csv"), io.load(b / "cleaned.csv")
    assert np.array_equal(tracked.times, mp.times) and tracked.names == mp.names
    assert np.all(np.isfinite(mp.values)) and np.abs(mp.values - tracked.values).max() > 1e-3
    assert (b / "one-euro.csv").is_file() and (b / "truth.csv").is_file()
    for folder in (a, b):
        assert (folder / "curves.png").read_bytes()[:8] == PNG

    iphone, mediapipe = _tables(said)
    assert tuple(iphone) == IPHONE_ROWS and tuple(mediapipe) == MEDIAPIPE_ROWS
    for table in (iphone, mediapipe):
        width = {len(cells) for cells in table.values()}
        assert width == {10}  # MSE x raw, 6 groups, blink, jitter, lag
        assert all(np.isfinite(c) for cells in table.values() for c in cells)
        raw_row = next(iter(table.values()))
        assert raw_row[:7] == [1.0] * 7  # every MSE column is a ratio to raw's
    assert mediapipe["--tracker mediapipe"][:7] != [1.0] * 7  # computed, not raw again
    # the demo says the default IS the tuned One Euro today: while it says so, it must be
    # (a default that differs needs that sentence changed, in demo.IPHONE)
    if "IS the tuned One Euro" in said:
        assert np.allclose(iphone["default"], iphone["one-euro (tuned)"], atol=0.011, rtol=0.01)

    legend = said[said.index("columns (both tables") :]
    for column in ("MSE x raw", "gaze..cheeks_nose", "blink closure", "jitter", "lag ms"):
        assert column in legend
    assert "never saw this performer" in said and "no shipped fit trains on" in said


def test_demo_refuses_a_bad_length(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "x"), "--seconds", "0"]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_the_demo_pair_is_small_package_data_the_project_made():
    files = [p for p in demo.PAIR.iterdir() if p.is_file()]
    assert sum(p.stat().st_size for p in files) < 300_000
    conf = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    globs = conf["tool"]["setuptools"]["package-data"]["faceclean"]
    for p in files:  # a wheel carries every file of it
        rel = p.relative_to(REPO / "src" / "faceclean").as_posix()
        assert any(fnmatch(rel, g) for g in globs), rel
    [pair] = paired.load(demo.PAIR)
    job = pair.meta["job"]
    # a synthetic performer of `pairs --seed 7`, never one of the training pairs' (--seed 0),
    # on a look no shipped fit trains on
    assert job["source"] == "synth:700000" and job["family"] == "groomed"
    assert pair.tracked.n_frames == pair.truth.n_frames > 100


def test_the_demo_runs_without_torch(tmp_path):
    """The demo is core: it must run where torch is not installed."""
    code = (
        "import sys\n"
        "class NoTorch:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'torch' or name.startswith('torch.'):\n"
        "            raise ImportError('torch is not installed (test)')\n"
        "sys.meta_path.insert(0, NoTorch())\n"
        "from faceclean.cli import main\n"
        f"sys.exit(main(['demo', '--out', {str(tmp_path)!r}, '--seconds', '3']))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stderr == ""  # no warnings either (make demo prints no deprecation noise)
