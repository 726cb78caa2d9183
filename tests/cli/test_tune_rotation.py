"""``tune --method rotation``: the head and eye angles' filter tuned on a take's own angles,
its preset used by ``clean --preset`` beside the blendshapes' cleaner."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, INDEX, POSE
from faceclean.cli import main

N = 600  # frames at 60 fps


def _take(noise: float, seed: int) -> Animation:
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 60.0
    v = np.zeros((N, 52))
    v[:, INDEX["jawOpen"]] = 0.3 + 0.2 * np.sin(2 * t)
    pose = np.zeros((N, 9))
    pose[:, 0] = 0.5 * np.sin(0.7 * t)  # the head turns
    pose[:, 3] = 0.2 * np.sin(1.3 * t)  # the left eye looks about
    pose += rng.normal(0, noise, pose.shape) * (np.arange(9) % 3 == 0)  # yaws jitter
    return Animation(t, v, ARKIT52, {"pose": pose, "pose_names": POSE})


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    d = tmp_path_factory.mktemp("rot")
    io.save(_take(0.02, 1), d / "noisy.csv", fmt="livelink")
    io.save(_take(0.0, 1), d / "truth.csv", fmt="livelink")
    return d


def test_tune_rotation_tunes_the_angles_per_group_and_clean_uses_it(takes, capsys):
    preset = takes / "rot.json"
    argv = ["tune", str(takes / "noisy.csv"), "--truth", str(takes / "truth.csv")]
    assert main([*argv, "--method", "rotation", "--per-group", "-o", str(preset)]) == 0
    doc = json.loads(preset.read_text())
    assert doc["method"] == "rotation" and set(doc["groups"]) == {"head", "eyes"}
    about = doc["about"]
    assert about["mse"]["head"] < 0.5 * about["raw_mse"]["head"]  # the jitter mostly gone
    out = takes / "out.csv"
    capsys.readouterr()
    assert main(["clean", str(takes / "noisy.csv"), "-o", str(out), "--method", "one-euro",
                 "--preset", str(preset)]) == 0  # fmt: skip
    said = capsys.readouterr().out
    assert "one-euro" in said and f"rotation (preset {preset})" in said
    from faceclean.filters import presets

    noisy, cleaned = io.load(takes / "noisy.csv"), io.load(out)
    want = presets.build(presets.read(preset), POSE).clean(
        Animation(noisy.times, noisy.meta["pose"], POSE)
    )
    got = cleaned.meta["pose"][:, : len(POSE)]
    np.testing.assert_allclose(got, want.values, atol=2e-9)  # Live Link's 10 decimals
    truth = io.load(takes / "truth.csv").meta["pose"][:, 0]
    assert np.mean((got[:, 0] - truth) ** 2) < 0.5 * np.mean(
        (noisy.meta["pose"][:, 0] - truth) ** 2
    )


def test_tune_rotation_refuses_takes_without_angles_in_one_line(tmp_path, capsys):
    p = tmp_path / "plain.csv"
    p.write_text("time,jawOpen\n0.0,0.1\n0.1,0.2\n")
    assert main(["tune", str(p), "--truth", str(p), "--method", "rotation", "-o",
                 str(tmp_path / "r.json")]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no head or eye angles" in err[0]
    assert not (tmp_path / "r.json").exists()


def test_a_blendshape_preset_is_not_taken_for_the_angles(tmp_path):
    from faceclean.errors import FacecleanError
    from faceclean.resolve import resolve

    with pytest.raises(FacecleanError, match="not one for head and eye angles"):
        resolve("one-euro", pose_preset="one-euro")
