"""The tracker table (evaluation/tracker_eval.py): folds, rows and the RESULTS section, on
a small folder of made-up pairs whose tracker under-reads every channel by a known gain and
offset (so the level-changing rows must beat the filters, and calibration must be near
exact)."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.evaluation import tracker_eval
from faceclean.synthetic import engine, rom
from faceclean.trackers.mediapipe import NAMES

GAIN, OFFSET = 0.6, 0.05  # the made-up tracker: x = GAIN y + OFFSET + noise
N = 240  # frames a pair (8 s at 30 fps)


def _tracker(t: np.ndarray, y: np.ndarray, rng) -> Animation:
    cols = [ARKIT52.index(n) for n in NAMES]
    x = GAIN * y[:, cols] + OFFSET + rng.normal(0, 0.01, (len(t), len(cols)))
    return Animation(t, x, NAMES)


def _performance(n: int, rng) -> np.ndarray:
    """(n, 52) smooth weights in [0, 1], independent per channel: low-passed noise."""
    w = rng.normal(0, 1, (n, 52))
    for _ in range(4):  # four passes of a 5-frame box: ~2 Hz at 30 fps
        w = np.apply_along_axis(lambda c: np.convolve(c, np.ones(5) / 5, "same"), 0, w)
    return np.clip(0.5 + 0.6 * w / w.std(), 0, 1)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("pairs")
    rng = np.random.default_rng(3)
    for g in ("a", "b", engine.SYNTH_GROUP):
        for k, setting in enumerate(("studio", "webcam", "window")):
            job = engine.Job(f"synth:{k}", g, 0.0, 8.0, seed=k, setting=setting, rate=30.0,
                             webcam=False)  # fmt: skip
            t = np.arange(N) / 30.0
            y = _performance(N, rng)
            meta = {"format": engine.FORMAT, "job": {"group": g, "setting": setting}}
            engine.write_pair(out, job.name, _tracker(t, y, rng), Animation(t, y, ARKIT52), meta)
            rt, ry = rom.clip(30.0)
            from faceclean import io

            if g != engine.SYNTH_GROUP:  # a fold without calibration clips: no such row
                io.save(_tracker(rt, ry, rng), engine.rom_path(out, job, "tracked"), fmt="csv")
            if g == "a":  # the clip's truth too: a training pair of its own
                io.save(Animation(rt, ry, ARKIT52), engine.rom_path(out, job, "truth"), fmt="csv")
    return out


@pytest.fixture(scope="module")
def result(folder):
    from faceclean.evaluation import tracker_eval

    return tracker_eval.evaluate(folder, held_out="window", work=folder / ".work")


@pytest.mark.slow
def test_every_fold_scores_every_row_and_level_rows_beat_the_filters(result):
    assert sorted(result["folds"]) == ["a", "b", engine.SYNTH_GROUP]
    overall = result["overall"]
    assert list(overall) == [
        "raw", "one-euro", "calibration + one-euro", "ridge map", "tracker map (ours)",
        "tracker map, detail 0", "tracker map, detail 1",
    ]  # fmt: skip
    raw = overall["raw"]["test"]["mse"]
    assert overall["one-euro"]["test"]["mse"] > 0.8 * raw  # a filter cannot fix levels
    for row in ("calibration + one-euro", "ridge map", "tracker map (ours)"):
        for split in ("test", "held"):
            assert overall[row][split]["mse"] < 0.2 * overall["raw"][split]["mse"], row
    assert overall["raw"]["held"]["pairs"] == 3 and overall["raw"]["test"]["pairs"] == 6
    # a fold whose test pairs lack calibration clips has no calibration row
    assert overall["calibration + one-euro"]["test"]["pairs"] == 4
    assert not any(k.startswith("calibration") for k in result["folds"][engine.SYNTH_GROUP])
    # "real": the synthetic performers' fold left out (2 test pairs a fold for a and b)
    assert result["real"]["raw"]["test"]["pairs"] == 4
    # each fold's tuned One Euro, as data (eval --pairs cleans the still face with it)
    assert set(result["one_euro"]) == set(result["folds"])
    for oe in result["one_euro"].values():
        assert (oe["min_cutoff"], oe["beta"]) in tracker_eval.ONE_EURO_GRID
    assert result["real"]["raw"]["held"]["pairs"] == 2


def test_calibration_clips_with_their_truth_train_as_pairs_of_their_own(folder):
    from faceclean.datasets import paired

    pairs = paired.load(folder, require_meta=True)
    with_truth = [p for p in pairs if p.rom_truth is not None]
    assert sorted({p.group for p in with_truth}) == ["a"] and len(with_truth) == 3
    both = paired.with_clips(pairs)
    clips = both[len(pairs) :]
    assert both[: len(pairs)] == pairs and len(clips) == 3
    assert paired.performances(both) == pairs  # what validation scores: no clip
    rt, ry = rom.clip(30.0)
    for clip, p in zip(clips, with_truth, strict=True):
        assert clip.name == f"{p.name}.rom" and (clip.group, clip.setting) == (p.group, p.setting)
        assert clip.tracked is p.rom
        np.testing.assert_allclose(clip.truth.arkit(ARKIT52)[0], ry, atol=1e-6)
        np.testing.assert_array_equal(clip.truth.times, p.rom.times)


def test_the_section_has_the_calibration_row_and_replaces_only_its_own(result):
    from faceclean.evaluation import tracker_results

    section = tracker_results.markdown(result)
    assert "| calibration + one-euro | test |" in section
    assert "Performances from the real ARKit takes" in section  # the real folds' own table
    assert section.count("| tracker map (ours) | test |") == 2
    page = "# Results\n\nkept\n\n" + tracker_results.BEGIN + "\nOLD-SECTION\n" + tracker_results.END
    new = tracker_results.insert(page, section)
    assert "kept" in new and "OLD-SECTION" not in new and new.count(tracker_results.BEGIN) == 1
