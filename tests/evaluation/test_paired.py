"""Pair folders: what `faceclean pairs` writes, and a studio's own raw/clean takes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.evaluation import paired


def _take(t, v, names=("jawOpen", "eyeBlinkLeft")):
    return Animation(t, v, names)


def test_engine_pairs_and_studio_pairs_are_found(tmp_path):
    t = np.arange(10) / 30
    v = np.tile([0.2, 0.4], (10, 1))
    io.save(_take(t, v), tmp_path / "a.tracked.csv")
    io.save(_take(t, v * 2), tmp_path / "a.truth.csv")
    meta = {"job": {"group": "perf1", "setting": "studio"}}
    (tmp_path / "a.json").write_text(json.dumps(meta))
    io.save(_take(t, v), tmp_path / "shot.raw.csv")
    io.save(_take(t[::2], v[::2] * 3), tmp_path / "shot.clean.csv")  # sampled apart
    io.save(_take(t, v), tmp_path / "lonely.tracked.csv")  # no partner: not a pair
    pairs = {p.name: p for p in paired.load(tmp_path)}
    assert sorted(pairs) == ["a", "shot"]
    assert (pairs["a"].group, pairs["a"].setting) == ("perf1", "studio")
    assert pairs["shot"].setting == "studio-take"
    y, _ = pairs["shot"].truth.arkit(ARKIT52)
    assert pairs["shot"].truth.n_frames == 10  # the truth at the tracked take's instants
    np.testing.assert_allclose(y[:9, ARKIT52.index("jawOpen")], 0.6)
    assert [p.name for p in paired.load(tmp_path, require_meta=True)] == ["a"]


def test_split_holds_out_a_source_and_a_render_setting(tmp_path):
    def pair(name, group, setting):
        a = _take([0.0, 0.1], [[0, 0], [0, 0]])
        return paired.Pair(name, a, a, group, setting)

    ps = [pair("1", "g1", "studio"), pair("2", "g2", "studio"), pair("3", "g2", "window"),
          pair("4", "g1", "window")]  # fmt: skip
    train, test, held = paired.split(ps, "g2", "window")
    assert [p.name for p in train] == ["1"]
    assert [p.name for p in test] == ["2"]
    assert [p.name for p in held] == ["3"]


def test_an_empty_folder_and_bad_metadata_are_one_line(tmp_path):
    with pytest.raises(FacecleanError, match="no pairs"):
        paired.load(tmp_path)
    with pytest.raises(FacecleanError, match="no such folder"):
        paired.load(tmp_path / "nope")
    t = np.arange(3) / 30
    io.save(_take(t, np.zeros((3, 2))), tmp_path / "a.tracked.csv")
    io.save(_take(t, np.zeros((3, 2))), tmp_path / "a.truth.csv")
    (tmp_path / "a.json").write_text("[" * 100_000)
    with pytest.raises(FacecleanError, match="a.json"):
        paired.load(tmp_path)
