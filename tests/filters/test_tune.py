"""Tuning, presets and the ``tune`` command."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, GROUPS
from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.evaluation import metrics
from faceclean.filters import make, presets, tune
from faceclean.filters.kalman import Kalman
from faceclean.filters.one_euro import OneEuro

NAMES = ("eyeBlinkLeft", "eyeBlinkRight", "jawOpen", "mouthClose", "browInnerUp")


def _pair(seed: int, noise=(0.05, 0.05, 0.005, 0.005, 0.005), seconds: float = 8.0):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.8, 1.2, int(60 * seconds)) / 60.0)
    f = rng.uniform(0.2, 0.8, len(NAMES))  # Hz
    truth = 0.5 + 0.3 * np.sin(2 * np.pi * f * t[:, None] + rng.uniform(0, 6, len(NAMES)))
    noisy = truth + rng.normal(0, 1, truth.shape) * np.array(noise)
    noisy[50:53] = np.nan  # tracking loss
    return Animation(t, noisy, NAMES), Animation(t, truth, NAMES)


def _mse(cleaner, pairs):
    return np.mean([metrics.mse(cleaner.clean(n).values, t.values) for n, t in pairs])


def test_tuned_ema_beats_raw_and_matches_a_brute_force_scan():
    pairs = [_pair(0), _pair(1)]
    result = tune.tune("ema", pairs)
    assert result.mse["all"] < 0.5 * result.raw_mse["all"]
    best = min(
        _mse(make("ema", {"tau": tau}, names=NAMES), pairs) for tau in np.geomspace(0.005, 0.5, 30)
    )
    tuned = _mse(result.build(NAMES), pairs)
    assert tuned <= best * 1.01


def test_per_group_gives_noisier_groups_more_smoothing_in_one_pass():
    pairs = [_pair(2), _pair(3)]
    result = tune.tune("one-euro", pairs, per_group=True)
    assert set(result.groups) == {"eyes", "jaw", "mouth", "brows"}
    assert result.groups["eyes"]["min_cutoff"] < result.groups["jaw"]["min_cutoff"]
    for g in result.groups:
        assert result.mse[g] < result.raw_mse[g]
    cleaner = result.build(NAMES)
    assert isinstance(cleaner, OneEuro)
    assert cleaner.min_cutoff.shape == (len(NAMES),)
    assert cleaner.min_cutoff[0] == pytest.approx(result.groups["eyes"]["min_cutoff"])
    assert cleaner.min_cutoff[2] == pytest.approx(result.groups["jaw"]["min_cutoff"])


@pytest.mark.parametrize("method", ["kalman", "gaussian", "savgol"])
def test_other_methods_tune_below_raw(method):
    pairs = [_pair(4, seconds=4.0)]
    result = tune.tune(method, pairs)
    assert result.mse["all"] < 0.5 * result.raw_mse["all"]
    assert _mse(result.build(NAMES), pairs) == pytest.approx(result.mse["all"], rel=0.05)


def test_tune_refuses_what_it_cannot_do():
    with pytest.raises(FacecleanError):
        tune.tune("lstm", [_pair(0)])
    with pytest.raises(FacecleanError):
        tune.tune("ema", [])


def test_align_interpolates_truth_at_noisy_times():
    t = np.arange(120) / 60.0
    clean = Animation(t, np.stack([t, 2 * t], axis=1), ["jawOpen", "mouthClose"])
    at = np.array([-0.5, 0.01, 0.5, 2.5])
    noisy = Animation(at, np.zeros((4, 2)), ["JawOpen", "MouthClose"])
    got = tune.align(noisy, clean).values
    assert np.isnan(got[0]).all() and np.isnan(got[3]).all()
    np.testing.assert_allclose(got[1:3], [[0.01, 0.02], [0.5, 1.0]], atol=1e-12)
    far = Animation(at + 100, np.zeros((4, 2)), ["jawOpen", "mouthClose"])
    with pytest.raises(FacecleanError):
        tune.align(far, clean)


def test_tune_on_a_truth_of_only_tracking_loss_is_one_line(tmp_path, capsys):
    # issue 19: frames all tracking loss, at other times than the noisy take's, ended in
    # "internal error: IndexError"
    noisy, _ = _pair(0, seconds=1.0)
    gone = Animation(noisy.times + 100.0, np.full(noisy.values.shape, np.nan), NAMES)
    io.save(noisy, tmp_path / "noisy.csv")
    io.save(gone, tmp_path / "truth.csv")
    argv = ["tune", str(tmp_path / "noisy.csv"), "--truth", str(tmp_path / "truth.csv")]
    assert main([*argv, "--method", "one-euro", "-o", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tracking loss" in err[0] and "internal error" not in err[0], err
    assert not (tmp_path / "p.json").exists()


def test_preset_round_trip_expands_groups(tmp_path):
    path = tmp_path / "k.json"
    presets.save(
        path, "kalman", {"q": 100.0, "r": 0.02}, {"eyes": {"q": 900.0}, "jaw": {"r": 0.05}}
    )
    doc = presets.read(path)
    assert doc["format"] == presets.FORMAT
    cleaner = presets.build(path, ARKIT52)
    assert isinstance(cleaner, Kalman)
    eyes = [ARKIT52.index(n) for n in GROUPS["eyes"]]
    jaw = [ARKIT52.index(n) for n in GROUPS["jaw"]]
    assert (cleaner.q[eyes] == 900.0).all() and cleaner.q[ARKIT52.index("jawOpen")] == 100.0
    assert (cleaner.r[jaw] == 0.05).all() and cleaner.r[0] == 0.02
    # Only mouth channels: every value agrees, so parameters stay scalars.
    small = presets.build(path, ["mouthClose", "mouthFunnel"])
    assert small.q.ndim == 0 and float(small.q) == 100.0
    over = presets.build(path, ARKIT52, overrides={"r": 0.1})
    assert float(over.r) == 0.1


@pytest.mark.parametrize("name", ["ema", "one-euro", "kalman"])
def test_shipped_presets_load_by_name(name):
    if name not in presets.shipped():
        pytest.skip(f"preset {name} not shipped yet")
    cleaner = presets.build(name, ARKIT52)
    assert cleaner.name == name
    doc = presets.read(name)
    assert set(doc["groups"]) == set(GROUPS)


@pytest.mark.parametrize(
    "text",
    [
        "{not json",
        "[1, 2]",
        '{"format": "faceclean-preset/2", "method": "ema", "params": {}}',
        '{"format": "faceclean-preset/1", "method": "magic", "params": {}}',
        '{"format": "faceclean-preset/1", "method": "ema", "params": {"tau": "0.1"}}',
        '{"format": "faceclean-preset/1", "method": "ema", "params": {"tau": true}}',
        '{"format": "faceclean-preset/1", "method": "ema", "params": {"tau": -1}}',
        '{"format": "faceclean-preset/1", "method": "ema", "params": {"bogus": 1}}',
        '{"format": "faceclean-preset/1", "method": "ema", "params": {}, "groups": {"ears": {}}}',
        '{"format": "faceclean-preset/1", "method": "ema", "params": {}, "extra": 1}',
        '{"format": "faceclean-preset/1", "method": "ema", "groups": {"eyes": {"tau": 0.1}}}',
    ],
)
def test_bad_presets_are_one_line_errors(tmp_path, text):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(FacecleanError) as e:
        presets.build(path, ARKIT52)
    assert "\n" not in str(e.value)


def test_missing_preset_names_the_shipped_ones():
    with pytest.raises(FacecleanError, match="no preset"):
        presets.build("does-not-exist", ARKIT52)


def test_tune_command_writes_a_preset_that_clean_loads(tmp_path, capsys):
    noisy, truth = _pair(5, seconds=4.0)
    io.save(noisy, tmp_path / "noisy.csv", fmt="csv")
    # The truth at other instants and in another format: tune interpolates it.
    fine = np.arange(0, 4.2, 1 / 120)
    io.save(
        tune.align(Animation(fine, np.zeros((len(fine), 5)), NAMES), truth), tmp_path / "truth.npz"
    )
    out = tmp_path / "preset.json"
    rc = main([
        "tune", str(tmp_path / "noisy.csv"), "--truth", str(tmp_path / "truth.npz"),
        "--method", "one-euro", "--per-group", "-o", str(out),
    ])  # fmt: skip
    assert rc == 0
    doc = json.loads(out.read_text())
    assert doc["method"] == "one-euro" and "eyes" in doc["groups"]
    assert "wrote" in capsys.readouterr().out
    rc = main(
        ["clean", str(tmp_path / "noisy.csv"), "-o", str(tmp_path / "c.csv"), "--preset", str(out)]
    )
    assert rc == 0 and (tmp_path / "c.csv").is_file()


def test_tune_command_bad_input_exits_2(tmp_path, capsys):
    noisy, truth = _pair(6, seconds=1.0)
    io.save(noisy, tmp_path / "n.csv", fmt="csv")
    out = tmp_path / "p.json"
    assert (
        main(["tune", str(tmp_path / "n.csv"), "--truth", str(tmp_path / "x.csv"), "-o", str(out)])
        == 2
    )
    assert (
        main(
            [
                "tune",
                str(tmp_path / "n.csv"),
                "--truth",
                str(tmp_path / "n.csv"),
                "--method",
                "lstm",
                "-o",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("faceclean:") == 2 and "Traceback" not in err
    assert not out.exists()
