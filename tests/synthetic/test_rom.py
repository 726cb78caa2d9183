"""The calibration clip (synthetic/rom.py) and its path through pairs, paired.load and the
calibration row of the tracker table."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.channels import ARKIT52
from faceclean.synthetic import rom


def test_the_clip_holds_neutral_then_takes_every_tracked_channel_to_its_full_range():
    t, w = rom.clip(30.0)
    assert w.shape == (len(t), 52) and t[-1] == pytest.approx(rom.seconds(), abs=1 / 30)
    assert np.all(w[t < rom.NEUTRAL_S - 1e-9] == 0.0)  # the neutral hold calibrate reads
    top = dict(zip(ARKIT52, w.max(axis=0), strict=True))
    assert top.pop("tongueOut") == 0.0  # MediaPipe has no tongue score
    assert top.pop("mouthClose") == pytest.approx(0.4)  # lips together, the jaw open 0.4
    assert min(top.values()) == pytest.approx(1.0)
    assert np.abs(np.diff(w, axis=0)).max() < 0.4  # eased in and out (30 Hz), never a jump


@pytest.mark.slow
def test_a_pairs_calibration_clip_is_rendered_loaded_and_calibrates(tmp_path):
    pytest.importorskip("numba")
    pytest.importorskip("mediapipe")
    from faceclean import io
    from faceclean.animation import Animation
    from faceclean.datasets import paired
    from faceclean.evaluation import tracker_eval
    from faceclean.settings import mesh_file, tracker_model
    from faceclean.synthetic import engine

    head, model = mesh_file("ict_full.npz"), tracker_model()
    if head is None or model is None:
        pytest.skip("shared ict_full.npz or face_landmarker.task absent")
    # 6 Hz: the whole clip in ~100 frames (a real job runs at 24-60 Hz)
    job = engine.Job("synth:1", "synthetic", 0.0, 2.0, seed=7, setting="studio", rate=6.0,
                     webcam=False)  # fmt: skip
    worker = engine.Worker(head, model)
    made = worker.run_rom(job, tmp_path)
    assert engine.rom_done(job, tmp_path) and made["frames"] == len(rom.clip(6.0)[0])
    # a pair beside it (its own frames do not matter here): the clip attaches to it
    times = np.arange(4) / 6.0
    rom_tracked = io.load(engine.rom_path(tmp_path, job, "tracked"))
    tracked = Animation(times, rom_tracked.values[:4], rom_tracked.names)
    truth = Animation(times, np.zeros((4, 52)), ARKIT52)
    engine.write_pair(
        tmp_path, job.name, tracked, truth, {"format": engine.FORMAT, "job": {"group": "synthetic"}}
    )
    (pair,) = paired.load(tmp_path, require_meta=True)  # the clip is not a pair of its own
    assert pair.rom is not None and pair.rom.n_frames == made["frames"]
    cleaner = tracker_eval.calibrated_one_euro(pair, 2.0, 0.0)
    # the levels map the neutral hold to 0 (its median: the offsets), the poses to the top
    levelled = cleaner.adjust.apply(pair.rom.values, pair.rom.names)
    hold = pair.rom.times < rom.NEUTRAL_S
    medians = np.nanmedian(levelled[hold], axis=0)  # 6 frames: a mean of the middle two
    assert np.nanmax(medians) < 0.1 and np.nanmedian(medians) < 1e-3
    assert np.nanmax(levelled) == 1.0 and np.isfinite(cleaner.clean(pair.rom).values).any()
