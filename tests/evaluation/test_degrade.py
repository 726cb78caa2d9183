"""The independent evaluation artefact model: contracts and the presence of each artefact."""

from __future__ import annotations

import numpy as np
import pytest

import faceclean
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, INDEX
from faceclean.errors import FacecleanError
from faceclean.evaluation.degrade import CONDITIONS, degrade
from faceclean.settings import takes_dir

TAKES = takes_dir()
needs_takes = pytest.mark.skipif(TAKES is None, reason="../shared/data/arkit_takes is absent")


def _cut(anim: Animation, seconds: float) -> Animation:
    keep = anim.times < anim.times[0] + seconds
    return Animation(anim.times[keep], anim.values[keep], anim.names)


@pytest.fixture(scope="module")
def happy() -> Animation:
    """A 60 fps real take (about 51 s), its first 30 s."""
    return _cut(faceclean.io.load(TAKES / "neurosync" / "Happy.csv"), 30.0)


@pytest.fixture(scope="module")
def apfel() -> Animation:
    """A 30 fps-row real take with 35 tracking-loss rows."""
    return faceclean.io.load(TAKES / "alexdjulin" / "apfel.csv")


def _synthetic(values_at, seconds: float = 30.0, fps: float = 60.0) -> Animation:
    t = np.arange(0, seconds, 1 / fps)
    x = np.zeros((len(t), 52))
    values_at(t, x)
    return Animation.from_arkit(t, x)


def _equal(a: Animation, b: Animation) -> bool:
    return np.array_equal(a.times, b.times) and np.array_equal(a.values, b.values, equal_nan=True)


@needs_takes
@pytest.mark.parametrize("condition", CONDITIONS)
def test_same_seed_is_bit_identical_and_seeds_differ(happy, condition):
    n1, t1 = degrade(happy, 11, condition)
    n2, t2 = degrade(happy, 11, condition)
    assert _equal(n1, n2) and _equal(t1, t2)
    n3, _ = degrade(happy, 12, condition)
    assert not _equal(n1, n3)


@needs_takes
@pytest.mark.parametrize("condition", ["30 fps", "60 fps", "120 fps"])
def test_rates_timestamps_and_truth_at_the_noisy_instants(happy, condition):
    noisy, truth = degrade(happy, 3, condition)
    f = float(condition.split()[0])
    assert noisy.names == truth.names == happy.names
    assert np.array_equal(noisy.times, truth.times)
    assert np.all(np.diff(noisy.times) > 0)
    assert abs(np.median(np.diff(noisy.times)) * f - 1) < 0.01
    assert abs(noisy.duration - happy.duration) < 1.0
    # truth is the clean take linearly interpolated at the noisy stamps
    want = np.stack([np.interp(noisy.times, happy.times, col) for col in happy.values.T], 1)
    np.testing.assert_allclose(truth.values, want, atol=1e-12)


@needs_takes
def test_webcam_is_irregular_with_drops(happy):
    noisy, truth = degrade(happy, 5, "webcam")
    dt = np.diff(noisy.times)
    assert np.all(dt > 0) and np.array_equal(noisy.times, truth.times)
    assert 22 < noisy.rate < 31
    assert np.std(dt) / np.mean(dt) > 0.05  # irregular stamps
    assert np.count_nonzero(dt > 1.6 * np.median(dt)) >= 3  # dropped frames leave gaps


@needs_takes
@pytest.mark.parametrize("condition", CONDITIONS)
def test_values_in_range_and_tracking_loss_rows(happy, condition):
    noisy, truth = degrade(happy, 21, condition, strength=2.0)
    v = noisy.values
    rows = np.isnan(v).any(axis=1)
    assert np.array_equal(rows, np.isnan(v).all(axis=1))  # NaN only as whole rows
    assert v[~rows].min() >= 0 and v[~rows].max() <= 1
    assert np.isfinite(truth.values).all()


@needs_takes
def test_strength_zero_gives_the_truth(happy):
    for condition in CONDITIONS:
        noisy, truth = degrade(happy, 4, condition, strength=0.0)
        np.testing.assert_allclose(noisy.values, np.clip(truth.values, 0, 1), atol=1e-12)
    dt = np.diff(degrade(happy, 4, "60 fps", strength=0.0)[0].times)
    assert np.ptp(dt) < 1e-9  # no late frames, no drops


@needs_takes
def test_noise_adds_high_frequency_energy_and_severity_is_realistic(happy):
    for condition in CONDITIONS:
        noisy, truth = degrade(happy, 8, condition)
        ok = noisy.valid
        hf_noisy = np.mean(np.diff(noisy.values[ok], 2, axis=0) ** 2)
        hf_truth = np.mean(np.diff(truth.values[ok], 2, axis=0) ** 2)
        assert hf_noisy > 3 * hf_truth
        mse = np.mean((noisy.values[ok] - truth.values[ok]) ** 2)
        assert 1e-4 < mse < 6e-3


@needs_takes
def test_blink_peaks_are_reduced_on_average(apfel):
    ratios = []
    for seed in range(6):
        noisy, truth = degrade(apfel, seed, "60 fps")
        for name in ("eyeBlinkLeft", "eyeBlinkRight"):
            tv, nv = truth.channel(name), noisy.channel(name)
            peak = (tv > 0.6) & (tv >= np.roll(tv, 1)) & (tv >= np.roll(tv, -1))
            peak &= np.isfinite(nv)
            ratios += list(nv[peak] / tv[peak])
    assert len(ratios) > 20
    assert np.mean(ratios) < 0.95


def test_jaw_leaks_into_mouth_channels():
    def jaw(t, x):
        x[:, INDEX["jawOpen"]] = 0.3 + 0.25 * np.sin(2 * np.pi * 0.7 * t)

    clean = _synthetic(jaw)
    targets = ("mouthClose", "mouthFunnel", "mouthLowerDownLeft", "mouthLowerDownRight")
    for seed in range(4):
        noisy, _ = degrade(clean, seed)
        v = noisy.values[noisy.valid]
        corr = [np.corrcoef(v[:, INDEX["jawOpen"]], v[:, INDEX[n]])[0, 1] for n in targets]
        assert max(corr) > 0.3
        brow = [
            abs(np.corrcoef(v[:, INDEX["jawOpen"]], v[:, INDEX[n]])[0, 1]) for n in ARKIT52[41:46]
        ]
        assert max(brow) < max(corr)


def test_noise_is_larger_mid_range():
    mouth = [j for j, n in enumerate(ARKIT52) if n.startswith("mouth")]

    def levels(t, x):
        x[:, mouth[::2]], x[:, mouth[1::2]] = 0.5, 0.12

    clean = _synthetic(levels)
    ratio = []
    for seed in range(4):
        noisy, _ = degrade(clean, seed)
        step = np.sqrt(np.mean(np.diff(noisy.values[noisy.valid], axis=0) ** 2, axis=0))
        ratio.append(np.median(step[mouth[::2]]) / np.median(step[mouth[1::2]]))
    assert np.mean(ratio) > 1.1


def test_resting_levels_drift_slowly():
    clean = _synthetic(lambda t, x: x.__setitem__(slice(None), 0.3), seconds=60.0, fps=30.0)
    noisy, truth = degrade(clean, 2, "30 fps")
    err = (noisy.values - truth.values)[noisy.valid]
    blocks = err[: len(err) // 60 * 60].reshape(-1, 60, 52).mean(axis=1)  # 2 s means
    assert np.median(blocks.std(axis=0)) > 0.005


@needs_takes
def test_webcam_repeats_frames_and_iphone_events_share_instants(happy):
    noisy, _ = degrade(happy, 9, "webcam")
    v, ok = noisy.values, noisy.valid
    frozen = np.all(v[1:] == v[:-1], axis=1) & ok[1:]
    assert np.count_nonzero(frozen) >= 3
    # one draw, three samplings: the tracking-loss windows sit at the same instants
    seed = next(s for s in range(50) if not degrade(happy, s, "30 fps", 3.0)[0].valid.all())
    lost = [degrade(happy, seed, c, 3.0)[0] for c in ("30 fps", "60 fps", "120 fps")]
    first = [a.times[~a.valid][0] for a in lost]
    assert np.ptp(first) < 1 / 30 + 1e-3


@needs_takes
def test_source_tracking_loss_is_dropped_from_both(apfel):
    assert not apfel.valid.all()
    for condition in ("60 fps", "webcam"):
        noisy, truth = degrade(apfel, 1, condition)
        assert np.isfinite(truth.values).all()
        # no output instant falls next to a missing source row
        i = np.searchsorted(apfel.times, noisy.times, "right") - 1
        nxt = np.minimum(i + 1, apfel.n_frames - 1)
        exact = apfel.times[i] == noisy.times
        assert np.all(apfel.valid[i] & (apfel.valid[nxt] | exact))


def test_bad_input_is_one_line_error():
    clean = _synthetic(lambda t, x: None, seconds=2.0)
    with pytest.raises(FacecleanError) as e:
        degrade(clean, 0, "90 fps")
    msg = str(e.value)
    assert "\n" not in msg and all(c in msg for c in CONDITIONS)
    with pytest.raises(FacecleanError):
        degrade(clean, 0, "60 fps", strength=-1.0)
    one = Animation(np.zeros(1), np.zeros((1, 52)), ARKIT52)
    with pytest.raises(FacecleanError):
        degrade(one, 0)
    backwards = Animation(np.array([0.0, 1.0, 0.5]), np.zeros((3, 52)), ARKIT52)
    with pytest.raises(FacecleanError):
        degrade(backwards, 0)
