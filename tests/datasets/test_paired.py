"""Pair folders: what `faceclean pairs` writes, and a studio's own raw/clean takes."""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.datasets import paired
from faceclean.errors import FacecleanError


def _take(t, v, names=("jawOpen", "eyeBlinkLeft")):
    return Animation(t, v, names)


def test_engine_pairs_and_studio_pairs_are_found(tmp_path):
    t = np.arange(10) / 30
    v = np.tile([0.2, 0.4], (10, 1))
    io.save(_take(t, v), tmp_path / "a.tracked.csv")
    io.save(_take(t, v * 2), tmp_path / "a.truth.csv")
    meta = {"format": "faceclean-pair/1", "job": {"group": "perf1", "setting": "studio"}}
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


def _pair(folder, name="a", truth_times=None, roles=("tracked", "truth")):
    t = np.arange(30) / 30
    tt = t if truth_times is None else truth_times
    io.save(_take(t, np.full((len(t), 2), 0.2)), folder / f"{name}.{roles[0]}.csv")
    io.save(_take(tt, np.full((len(tt), 2), 0.4)), folder / f"{name}.{roles[1]}.csv")


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ('{"format": "faceclean-pair/999", "job": {}}', "format 'faceclean-pair/999'"),
        ('{"format": "faceclean-animation/1"}', "format 'faceclean-animation/1'"),
        ('{"job": {}}', "no 'format'"),
        ("42", "not a JSON object"),
        ('{"format": "faceclean-pair/1", "x": NaN}', "a.json"),
    ],
)
def test_pair_metadata_of_another_format_is_refused_not_skipped(tmp_path, text, said):
    _pair(tmp_path)
    (tmp_path / "a.json").write_text(text)
    with pytest.raises(FacecleanError, match=re.escape(said)):
        paired.load(tmp_path)


def test_a_pair_file_that_is_a_fifo_is_refused_not_skipped(tmp_path):
    _pair(tmp_path)
    os.mkfifo(tmp_path / "a.json")
    with pytest.raises(FacecleanError, match="a FIFO, not a regular file"):
        paired.load(tmp_path)
    (tmp_path / "a.json").unlink()
    (tmp_path / "a.truth.csv").unlink()
    os.mkfifo(tmp_path / "a.truth.csv")
    with pytest.raises(FacecleanError, match="a FIFO, not a regular file"):
        paired.load(tmp_path)


@pytest.mark.parametrize(
    "truth_times",
    [np.arange(30) / 30 + 0.01, np.arange(29) / 30, np.arange(15) / 7 + 500],
    ids=["shifted-10ms", "one-frame-short", "elsewhere"],
)
def test_tracked_and_truth_must_share_their_instants(tmp_path, truth_times):
    _pair(tmp_path, truth_times=truth_times)
    with pytest.raises(FacecleanError, match="a: the truth take's instants are not the tracked"):
        paired.load(tmp_path)


def test_tracked_and_truth_within_half_a_millisecond_are_one_pair(tmp_path):
    _pair(tmp_path, truth_times=np.arange(30) / 30 + 3e-4)
    (p,) = paired.load(tmp_path)
    np.testing.assert_array_equal(p.truth.times, np.arange(30) / 30)


@pytest.mark.parametrize(
    "clean_times",
    [np.arange(30) / 30 + 1000.0, np.arange(10) / 30, np.arange(30) / 30 + 0.5],
    ids=["elsewhere", "a third", "late-start"],
)
def test_a_clean_take_must_cover_the_raw_instants(tmp_path, clean_times):
    _pair(tmp_path, "shot", clean_times, roles=("raw", "clean"))
    with pytest.raises(FacecleanError, match="shot: the clean take .* does not cover"):
        paired.load(tmp_path)


def test_a_clean_take_going_backwards_is_refused(tmp_path):
    _pair(tmp_path, "shot", np.arange(20)[::-1] / 20, roles=("raw", "clean"))
    with pytest.raises(FacecleanError, match="shot: the clean take: row 2"):
        paired.load(tmp_path)
