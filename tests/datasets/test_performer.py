"""The synthetic performer: human blink timing, coherent gaze, speech, range, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean import io
from faceclean.channels import ARKIT52, INDEX
from faceclean.cli import main
from faceclean.datasets import performer
from faceclean.errors import FacecleanError


@pytest.fixture(scope="module")
def take():
    return performer.perform(120.0, seed=7)


def col(anim, name):
    return anim.values[:, INDEX[name]]


def blink_count(curve: np.ndarray) -> int:
    return int(np.sum((curve[1:] >= 0.5) & (curve[:-1] < 0.5)))


def test_shape_range_and_determinism(take):
    assert take.names == ARKIT52 and take.n_frames == 7201
    assert np.allclose(np.diff(take.times), 1 / 60)
    assert take.values.min() >= 0.0 and take.values.max() <= 1.0
    again = performer.perform(120.0, seed=7)
    assert np.array_equal(take.values, again.values)
    assert not np.array_equal(take.values, performer.perform(120.0, seed=8).values)


@pytest.mark.parametrize("seed", [0, 7, 11])
def test_blinks_are_human(seed):
    anim = performer.perform(120.0, seed=seed)
    left, right = col(anim, "eyeBlinkLeft"), col(anim, "eyeBlinkRight")
    assert 8 <= blink_count(left) / 2.0 <= 30
    assert np.corrcoef(left, right)[0, 1] > 0.8
    assert not np.array_equal(left, right)  # slight asymmetry


def test_blink_closes_faster_than_it_opens(take):
    b, t = col(take, "eyeBlinkLeft"), take.times
    k = int(np.argmax(b))
    up = t[k] - t[: k + 1][b[: k + 1] < 0.2 * b[k]][-1]
    down = t[k:][b[k:] < 0.2 * b[k]][0] - t[k]
    assert 0.04 < up < down < 0.4


def test_gaze_channels_are_consistent(take):
    out_l, in_r = col(take, "eyeLookOutLeft"), col(take, "eyeLookInRight")
    in_l = col(take, "eyeLookInLeft")
    assert np.corrcoef(out_l, in_r)[0, 1] > 0.8  # looking left moves both eyes left
    assert np.corrcoef(out_l, in_l)[0, 1] < 0.0  # one eye never looks both ways


def test_many_channels_move_and_the_jaw_speaks(take):
    assert (take.values.std(0) > 0.01).sum() > 20
    jaw = col(take, "jawOpen")
    assert jaw.std() > 0.03
    spectrum = np.abs(np.fft.rfft(jaw - jaw.mean())) ** 2
    freq = np.fft.rfftfreq(len(jaw), 1 / 60)
    assert spectrum[(freq > 2) & (freq < 8)].sum() > 0.1 * spectrum[freq > 0.5].sum()


def test_netted_opposites_keep_their_difference_and_are_never_held_at_once():
    x = performer.independent(30.0, seed=3).values
    y = performer.independent(30.0, seed=3, net=True).values
    moved = 0
    for a, b in performer.OPPOSITES:
        i, j = INDEX[a], INDEX[b]
        assert np.allclose(y[:, i] - y[:, j], x[:, i] - x[:, j])  # what a face shows
        assert not ((y[:, i] > 0) & (y[:, j] > 0)).any()
        moved += int(((x[:, i] > 0.1) & (x[:, j] > 0.1)).sum())
    assert moved > 100  # drawn on their own, the opposites were held at once
    others = [k for k in range(52) if ARKIT52[k] not in sum(performer.OPPOSITES, ())]
    assert np.array_equal(y[:, others], x[:, others])
    full = performer.perform(30.0, seed=3, full_range=True, net=True).values
    assert full.min() >= 0.0 and full.max() <= 1.0


def test_other_rates_and_bad_arguments():
    assert performer.perform(2.0, seed=1, fps=30.0).n_frames == 61
    for bad in (dict(seconds=0.0), dict(seconds=float("nan")), dict(seconds=1.0, fps=0.0)):
        with pytest.raises(FacecleanError):
            performer.perform(seed=0, **bad)


def test_synth_command_writes_a_plain_csv(tmp_path, capsys):
    out = tmp_path / "s.csv"
    args = ["synth", "-o", str(out), "--seconds", "3", "--seed", "7", "--fps", "30"]
    assert main(args) == 0
    header = out.read_text().splitlines()[0].split(",")
    assert header == ["time", *ARKIT52]
    back = io.load(out)
    assert np.array_equal(back.values, performer.perform(3.0, 7, 30.0).values)
    first = out.read_bytes()
    assert main(args) == 0 and out.read_bytes() == first
    assert main(["synth", "-o", str(tmp_path / "x.csv"), "--seconds", "-1"]) == 2
    assert "faceclean: " in capsys.readouterr().err
