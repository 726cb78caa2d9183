"""``faceclean demo``: the main job end to end writes real, readable files."""

from __future__ import annotations

import numpy as np

from faceclean import io
from faceclean.cli import main
from faceclean.evaluation import metrics


def test_demo_cleans_the_example_clip(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--seconds", "6", "--seed", "3"]) == 0
    said = capsys.readouterr().out
    noisy = io.load(tmp_path / "noisy.csv")
    cleaned = io.load(tmp_path / "cleaned.csv")
    truth = io.load(tmp_path / "truth.csv")
    assert noisy.meta["format"] == "livelink"  # the example is a Live Link Face take
    assert cleaned.meta["format"] == "livelink"
    assert np.array_equal(noisy.times, cleaned.times)
    assert (tmp_path / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the cleaner removed jitter the input had
    raw, got = metrics.summary(noisy, truth), metrics.summary(cleaned, truth)
    assert got["jitter_ratio"] < raw["jitter_ratio"]
    assert "raw input" in said and "cleaned with" in said


def test_demo_refuses_a_bad_length(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "x"), "--seconds", "0"]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "x").exists()
