"""The tracker-artefact simulator: determinism, range, and every artefact on its own."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import INDEX
from faceclean.cli import main
from faceclean.datasets import performer, simulate
from faceclean.datasets.simulate import Params
from faceclean.errors import FacecleanError
from faceclean.settings import takes_dir
from faceclean.timing import resample, runs


@pytest.fixture(scope="module")
def clean() -> Animation:
    return performer.perform(20.0, seed=1, fps=60.0)


def only(clean: Animation, seed: int = 0, **kw) -> tuple[Animation, Animation]:
    """Apply a Params with nothing but ``kw`` enabled."""
    return simulate.apply(clean, Params(**kw), np.random.default_rng(seed))


def d2_energy(anim: Animation) -> float:
    """Mean squared second difference over valid consecutive frames and channels."""
    d2 = np.diff(anim.values, 2, axis=0)
    return float(np.nanmean(d2**2))


def col(anim: Animation, name: str) -> np.ndarray:
    return anim.channel(name)


def test_same_seed_same_arrays_other_seed_other_arrays(clean):
    a_noisy, a_truth = simulate.corrupt(clean, seed=5, preset="webcam")
    b_noisy, b_truth = simulate.corrupt(clean, seed=5, preset="webcam")
    c_noisy, _ = simulate.corrupt(clean, seed=6, preset="webcam")
    assert np.array_equal(a_noisy.times, b_noisy.times)
    assert np.array_equal(a_noisy.values, b_noisy.values, equal_nan=True)
    assert np.array_equal(a_truth.values, b_truth.values, equal_nan=True)
    assert a_noisy.n_frames != c_noisy.n_frames or not np.allclose(
        a_noisy.values, c_noisy.values, equal_nan=True
    )


def test_cli_output_is_byte_identical_for_a_seed(tmp_path, clean):
    src = tmp_path / "clean.csv"
    io.save(clean, src)
    outs = []
    for k in range(2):
        out, truth = tmp_path / f"noisy{k}.csv", tmp_path / f"truth{k}.csv"
        assert (
            main(["corrupt", str(src), "-o", str(out), "--seed", "3", "--truth-out", str(truth)])
            == 0
        )
        outs.append((out.read_bytes(), truth.read_bytes()))
    assert outs[0] == outs[1]
    assert main(["corrupt", str(src), "-o", str(tmp_path / "x.csv"), "--seed", "4"]) == 0
    assert (tmp_path / "x.csv").read_bytes() != outs[0][0]
    noisy, truth = io.load(tmp_path / "noisy0.csv"), io.load(tmp_path / "truth0.csv")
    assert np.array_equal(noisy.times, truth.times)
    assert d2_energy(noisy) > 3.0 * d2_energy(truth)


def test_cli_refuses_bad_input_with_one_line(tmp_path, capsys):
    assert (
        main(["corrupt", str(tmp_path / "none.csv"), "-o", str(tmp_path / "o.csv"), "--seed", "1"])
        == 2
    )
    assert capsys.readouterr().err.startswith("faceclean: ")
    assert not (tmp_path / "o.csv").exists()


def test_a_take_whose_times_span_years_is_refused_before_any_memory_is_asked(tmp_path, capsys):
    # times a million times off (or one 1e7 s gap): numpy asked 116 GiB, its own words
    t = np.arange(301) / 60.0 * 1e6
    take = tmp_path / "far.csv"
    io.save(Animation(t, np.full((301, 2), 0.2), ("jawOpen", "eyeBlinkLeft")), take)
    assert main(["corrupt", str(take), "-o", str(tmp_path / "o.csv"), "--seed", "1"]) == 2
    err = capsys.readouterr().err
    assert "frames at 60 Hz (at most 4,000,000; are its times in s?)" in err, err
    assert not (tmp_path / "o.csv").exists()
    assert main(["synth", "-o", str(tmp_path / "s.npz"), "--seconds", "86400", "--fps",
                 "1000"]) == 2  # fmt: skip
    assert "8.64e+07 frames (at most 4,000,000)" in capsys.readouterr().err


@pytest.mark.parametrize("preset", sorted(simulate.PRESETS))
def test_values_stay_in_the_channel_range_and_truth_at_noisy_times(clean, preset):
    noisy, truth = simulate.corrupt(clean, seed=2, preset=preset, strength=2.0)
    assert np.nanmin(noisy.values) >= 0.0 and np.nanmax(noisy.values) <= 1.0
    assert np.array_equal(noisy.times, truth.times) and np.all(np.diff(noisy.times) > 0)
    assert noisy.names == truth.names == clean.names
    assert truth.valid.all()  # the truth keeps values through tracking loss
    expect = resample(clean.times, clean.values, truth.times)
    assert np.allclose(truth.values, expect)


def test_nothing_enabled_gives_the_resampled_truth(clean):
    noisy, truth = only(clean)
    assert np.array_equal(noisy.values, np.clip(truth.values, 0.0, 1.0))
    zero, _ = simulate.corrupt(clean, seed=1, strength=0.0)
    assert np.allclose(
        zero.values, np.clip(simulate.corrupt(clean, 1, strength=0.0)[1].values, 0, 1)
    )


def test_iphone_preset_triples_the_jitter_energy(clean):
    for seed in range(3):
        noisy, truth = simulate.corrupt(clean, seed=seed, preset="iphone")
        assert d2_energy(noisy) > 3.0 * d2_energy(truth)


@pytest.mark.skipif(takes_dir() is None, reason="shared data folder absent")
def test_iphone_preset_triples_the_jitter_energy_of_a_real_take():
    take = io.load(takes_dir() / "neurosync" / "MySlate_161_iPhone_cal.csv")
    noisy, truth = simulate.corrupt(take, seed=0, preset="iphone")
    assert d2_energy(noisy) > 3.0 * d2_energy(truth)


def test_jitter_alone_raises_second_difference_energy(clean):
    noisy, truth = only(clean, jitter=0.01)
    assert d2_energy(noisy) > 3.0 * d2_energy(truth)
    resid = noisy.values - truth.values
    assert 0.003 < np.std(resid[:, INDEX["browInnerUp"]]) < 0.02


def test_velocity_jitter_is_larger_when_a_channel_moves_fast(clean):
    noisy, truth = only(clean, jitter_velocity=0.005)
    blink = col(truth, "eyeBlinkLeft")
    speed = np.abs(np.gradient(blink, truth.times))
    err = np.abs(col(noisy, "eyeBlinkLeft") - blink)
    assert err[speed > 3.0].mean() > 10.0 * max(err[speed < 0.05].mean(), 1e-6)


def test_saturation_alone_lowers_blink_peaks_and_spares_small_values(clean):
    noisy, truth = only(clean, blink_peak=0.7)
    assert col(truth, "eyeBlinkLeft").max() > 0.9
    assert col(noisy, "eyeBlinkLeft").max() < 0.75
    small = col(truth, "eyeBlinkLeft") < 0.2
    assert np.allclose(
        col(noisy, "eyeBlinkLeft")[small], col(truth, "eyeBlinkLeft")[small], atol=2e-3
    )
    top, _ = only(clean, peak=0.8)
    assert col(top, "mouthSmileLeft").max() < col(truth, "mouthSmileLeft").max()


def test_crosstalk_jaw_leaks_jaw_open_into_mouth_close(clean):
    noisy, truth = only(clean, crosstalk_jaw=0.2)
    leak = col(noisy, "mouthClose") - col(truth, "mouthClose")
    assert np.allclose(leak, 0.2 * col(truth, "jawOpen"), atol=1e-9)
    others = [n for n in truth.names if n != "mouthClose"]
    assert all(np.array_equal(col(noisy, n), np.clip(col(truth, n), 0, 1)) for n in others)


def test_crosstalk_left_right_and_brows(clean):
    noisy, truth = only(clean, crosstalk_lr=0.1)
    resid = col(noisy, "mouthSmileLeft") - col(truth, "mouthSmileLeft")
    other = col(truth, "mouthSmileRight") - col(truth, "mouthSmileLeft")
    share = np.dot(resid, other) / np.dot(other, other)
    assert 0.04 < share < 0.11
    noisy, truth = only(clean, crosstalk_brow=0.2)
    assert np.all(col(noisy, "browInnerUp") >= col(truth, "browInnerUp") - 1e-12)
    assert np.any(col(noisy, "browInnerUp") > col(truth, "browInnerUp") + 0.01)


def test_drift_alone_is_a_slow_bias(clean):
    noisy, truth = only(clean, drift=0.03, drift_period=5.0)
    resid = noisy.values - np.clip(truth.values, 0, 1)
    assert np.std(resid) > 0.005
    assert np.mean(np.diff(resid, 2, axis=0) ** 2) < 1e-2 * np.mean(resid**2)


def test_spikes_hit_a_few_channels_for_a_few_frames(clean):
    noisy, truth = only(clean, spike_rate=1.0, spike_amplitude=0.5, spike_duration=0.05)
    hit = np.abs(noisy.values - np.clip(truth.values, 0, 1)) > 0.05  # (N, M)
    frames = hit.any(1)
    assert 5 <= frames.sum() < 0.2 * len(frames)
    assert hit[frames].sum(1).max() <= 5 and hit[frames].sum(1).max() >= 2


def test_frozen_frames_repeat_the_last_solve(clean):
    noisy, truth = only(clean, freeze_rate=0.1)
    same = np.all(noisy.values[1:] == noisy.values[:-1], axis=1)
    moved = np.any(truth.values[1:] != truth.values[:-1], axis=1)
    assert (same & moved).mean() > 0.05
    assert noisy.n_frames == truth.n_frames


def test_drops_remove_frames_from_both(clean):
    full, _ = only(clean)
    noisy, truth = only(clean, drop_rate=0.1, drop_burst=3.0)
    assert noisy.n_frames < 0.95 * full.n_frames
    assert np.array_equal(noisy.times, truth.times)
    assert np.diff(noisy.times).max() > 2.5 / 60.0
    assert np.isin(noisy.times, full.times).all()


def test_tracking_loss_gaps_are_nan_rows_with_truth_kept(clean):
    noisy, truth = only(clean, loss_rate=6.0, loss_duration=0.5)
    lost = ~noisy.valid
    assert 0 < lost.sum() < noisy.n_frames
    assert np.isnan(noisy.values[lost]).all() and truth.valid.all()


def test_irregular_timing_and_rate(clean):
    noisy, _ = only(clean, fps=30.0, timing_irregularity=0.3)
    dt = np.diff(noisy.times)
    assert abs(1.0 / dt.mean() - 30.0) < 3.0
    assert dt.std() / dt.mean() > 0.15 and dt.min() > 0
    regular, _ = only(clean, fps=120.0)
    assert np.allclose(np.diff(regular.times), 1.0 / 120.0)


def test_missing_source_rows_are_missing_in_truth_and_noisy():
    t = np.arange(300) / 60.0
    x = np.full((300, 52), 0.3)
    x[100:130] = np.nan
    noisy, truth = simulate.corrupt(Animation.from_arkit(t, x), seed=0, preset="clean")
    gap = (truth.times > 100 / 60) & (truth.times < 129 / 60)
    assert gap.any() and not truth.valid[gap].any() and not noisy.valid[gap].any()
    assert truth.valid[~gap].sum() > 250


def test_bad_input_raises_one_line_errors(clean):
    with pytest.raises(FacecleanError, match="preset"):
        simulate.corrupt(clean, seed=0, preset="nope")
    with pytest.raises(FacecleanError, match="strength"):
        simulate.corrupt(clean, seed=0, strength=float("nan"))
    with pytest.raises(FacecleanError, match="2 valid frames"):
        simulate.corrupt(Animation.from_arkit([0.0], np.zeros((1, 52))), seed=0)


def test_sample_params_follow_preset_ranges_and_strength():
    rng = np.random.default_rng(0)
    for _ in range(20):
        p = simulate.sample_params(rng, "mixed")
        assert 24.0 <= p.fps <= 120.0 and 0.55 <= p.blink_peak <= 0.92
    weak = simulate.sample_params(np.random.default_rng(1), "webcam", 0.5)
    full = simulate.sample_params(np.random.default_rng(1), "webcam", 1.0)
    assert weak.jitter == pytest.approx(0.5 * full.jitter) and weak.fps == full.fps
    assert 1.0 - weak.blink_peak == pytest.approx(0.5 * (1.0 - full.blink_peak))


def test_resample_is_exact_at_source_frames_and_never_bridges_missing_rows():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    x = np.array([[0.0], [1.0], [np.nan], [3.0]])
    got = resample(t, x, np.array([0.0, 0.5, 1.0, 1.5, 2.5, 3.0, 4.0]))
    assert np.allclose(got[[0, 1, 2, 5, 6], 0], [0.0, 0.5, 1.0, 3.0, 3.0])
    assert np.isnan(got[[3, 4], 0]).all()


def test_runs_have_the_requested_share():
    mask = runs(100_000, 0.01, 4.0, np.random.default_rng(0))
    assert 0.03 < mask.mean() < 0.05


def _posed(clean: Animation, yaw0: float = 0.0) -> Animation:
    """``clean`` as a Live Link take with head and eye angles: a slow head turn about
    ``yaw0`` (rad) and still eyes."""
    from faceclean.channels import POSE

    t = clean.times - clean.times[0]
    pose = np.zeros((clean.n_frames, 9))
    pose[:, 0] = simulate_wrap(yaw0 + 0.3 * np.sin(2 * np.pi * t / 8.0))
    pose[:, 1] = 0.1 * np.sin(2 * np.pi * t / 5.0)
    pose[:, 4] = 0.05
    meta = {"format": "livelink", "pose": pose, "pose_names": POSE}
    return Animation(clean.times, clean.values, clean.names, meta)


def simulate_wrap(a):
    from faceclean.filters.rotation import wrap

    return wrap(a)


@pytest.mark.parametrize("yaw0", [0.0, np.pi])  # pi: the head faces the +-pi cut
def test_head_and_eye_angles_go_through_with_the_live_link_noise(clean, yaw0):
    """Review: ``corrupt`` on a Live Link take wrote a plain CSV without its angles."""
    from faceclean.channels import POSE
    from faceclean.filters.rotation import wrap

    take = _posed(clean, yaw0)
    noisy, truth = simulate.corrupt(take, seed=4, preset="iphone")
    plain, _ = simulate.corrupt(clean, seed=4, preset="iphone")
    np.testing.assert_array_equal(noisy.values, plain.values)  # the blendshapes as before
    assert noisy.meta["format"] == truth.meta["format"] == "livelink"
    assert tuple(noisy.meta["pose_names"]) == POSE
    p, q = np.asarray(noisy.meta["pose"]), np.asarray(truth.meta["pose"])
    assert p.shape == q.shape == (noisy.n_frames, 9)
    # the truth is the take's angles at the noisy stream's times, the short way round
    want = wrap(yaw0 + 0.3 * np.sin(2 * np.pi * (noisy.times - clean.times[0]) / 8.0))
    np.testing.assert_allclose(wrap(q[:, 0] - want), 0.0, atol=2e-3)
    err = wrap(p - q)[noisy.valid]
    ok = np.abs(err).max(axis=1) < 0.03  # outliers (3 deg, 0.052 rad) aside: 4 sd of the most
    assert 0.95 < ok.mean() < 1.0
    np.testing.assert_allclose(err[ok].std(axis=0), simulate.POSE_JITTER, rtol=0.25)
    assert np.isnan(p[~noisy.valid]).all()  # lost tracking: the angles too


def test_corrupt_keeps_a_live_link_take_live_link_with_its_angles(tmp_path, clean):
    src, out, truth = tmp_path / "take.csv", tmp_path / "noisy.csv", tmp_path / "truth.csv"
    io.save(_posed(clean), src, fmt="livelink")
    args = ["corrupt", str(src), "-o", str(out), "--seed", "2", "--truth-out", str(truth)]
    assert main(args) == 0
    back, want = io.load(out), io.load(truth)
    assert back.meta["format"] == "livelink" and "HeadYaw" in back.meta["pose_names"]
    assert np.isfinite(np.asarray(want.meta["pose"])).all()
    tuned = tmp_path / "rot.json"  # what the review could not do: tune the angles on it
    assert (
        main(["tune", str(out), "--truth", str(truth), "--method", "rotation", "-o", str(tuned)])
        == 0
    )


def test_a_channel_never_tracked_stays_missing_and_the_others_keep_their_frames(clean):
    # one channel NaN throughout (and another's cells here and there): the crosstalk once
    # mixed those NaNs into every channel, and every frame came out a tracking loss
    x = clean.values.copy()
    x[:, clean.names.index("jawOpen")] = np.nan
    x[::7, clean.names.index("mouthSmileLeft")] = np.nan
    holed = clean.with_values(x)
    noisy, truth = simulate.corrupt(holed, seed=3, preset="iphone")
    whole, _ = simulate.corrupt(clean, seed=3, preset="iphone")
    lost = np.isnan(noisy.values).all(axis=1)
    assert lost.sum() == np.isnan(whole.values).all(axis=1).sum() < 0.1 * noisy.n_frames
    assert np.isnan(col(noisy, "jawOpen")).all() and np.isnan(col(truth, "jawOpen")).all()
    others = [j for j, n in enumerate(noisy.names) if n not in ("jawOpen", "mouthSmileLeft")]
    assert np.isfinite(noisy.values[~lost][:, others]).all()
