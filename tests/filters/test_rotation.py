"""The rotation filter (head and eye angles): wrap-safe, the time rules, per-group
settings, the shipped tuned preset, and the angles cleaned through ``clean`` and ``info``."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean import Cleaner, io
from faceclean.animation import Animation
from faceclean.channels import POSE, POSE_GROUPS
from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.filters import make, presets
from faceclean.filters.rotation import Rotation, clean_pose, pose_matches, wrap
from faceclean.io import stream
from faceclean.resolve import resolve
from faceclean.settings import takes_dir

TAKES = takes_dir()
HEAD_TAKE = TAKES / "sentien" / "MySlate_24_iPhone.csv" if TAKES else None  # the head moves
needs_takes = pytest.mark.skipif(TAKES is None, reason="../shared/data/arkit_takes is absent")


def _turning(n: int = 240, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(n,) s at 60 fps, (n,) rad: a yaw turning steadily through the +-pi cut, jittered."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 60.0
    return t, wrap(2.6 + 1.2 * t + rng.normal(0.0, 0.01, n))


def test_a_turn_through_the_cut_moves_the_short_way():
    t, x = _turning()
    y = np.array([r[0] for r in _stepped(Rotation(names=["HeadYaw"]), t, x[:, None])])
    plain = np.array([r[0] for r in _stepped(make("one-euro", names=["HeadYaw"]), t, x[:, None])])
    assert np.abs(wrap(np.diff(y))).max() < 0.1  # rad per frame: no sweep round the circle
    assert np.abs(wrap(y - x)).max() < 0.15  # and it follows the input on the circle
    assert np.abs(wrap(plain - x)).max() > 0.3  # a filter on raw numbers sweeps round
    assert np.abs(y).max() < np.pi + 0.15  # beside the input, never a whole turn away


def test_away_from_the_cut_it_is_one_euro():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 0.03, 200))
    x = 0.3 * np.sin(t)[:, None] + rng.normal(0, 0.01, (200, 3))
    names = POSE_GROUPS["head"]
    a = _stepped(Rotation(min_cutoff=2.0, beta=0.5, names=names), t, x)
    b = _stepped(make("one-euro", {"min_cutoff": 2.0, "beta": 0.5}, names=names), t, x)
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_time_rules_hold_as_for_blendshapes():
    c = Rotation(names=POSE)
    x = np.full(9, 0.2)
    c.step(x, 0.0)
    held = c.step(x + 0.1, 1 / 60)
    np.testing.assert_array_equal(c.step(np.full(9, np.nan), 2 / 60), held)  # tracking loss
    np.testing.assert_array_equal(c.step(x + 3.0, 1 / 60), held)  # not after the last frame
    np.testing.assert_array_equal(c.step(x - 1.0, 5.0), x - 1.0)  # after a gap: restart


def test_groups_and_names_pick_the_angles():
    assert [n for n in POSE if pose_matches("head", n)] == list(POSE[:3])
    assert [n for n in POSE if pose_matches("eyes", n)] == list(POSE[3:])
    assert [n for n in POSE if pose_matches("LeftEye*", n)] == list(POSE[3:6])
    assert pose_matches("headyaw", "HeadYaw") and not pose_matches("head", "jawOpen")


def test_the_shipped_preset_is_tuned_per_group():
    doc = presets.read("rotation")
    assert doc["method"] == "rotation" and set(doc["groups"]) == {"head", "eyes"}
    assert doc["about"]["script"] == "benchmarks/tune_rotation.py"
    for g in ("head", "eyes"):  # tuning beat the raw angles on its own pairs
        assert doc["about"]["mse"][g] < doc["about"]["raw_mse"][g]
    built = resolve().build_pose(POSE)
    np.testing.assert_array_equal(built.min_cutoff[:3], doc["groups"]["head"]["min_cutoff"])
    np.testing.assert_array_equal(built.min_cutoff[3:], doc["groups"]["eyes"]["min_cutoff"])


def test_set_head_and_eyes_reach_the_rotation_filter():
    c = resolve(None, ["head.min_cutoff=0.5", "RightEyeYaw.beta=7"]).build_pose(POSE)
    assert list(c.min_cutoff[:3]) == [0.5] * 3 and c.min_cutoff[3] != 0.5
    assert c.beta[6] == 7 and c.beta[5] != 7
    # eyes.KEY names the eye blendshapes and the eye angles: each side that has the key
    choice = resolve("one-euro", ["eyes.min_cutoff=0.25"])
    assert choice.build(["eyeBlinkLeft", "jawOpen"]).min_cutoff.tolist()[0] == 0.25
    assert choice.build_pose(POSE).min_cutoff[3:].tolist() == [0.25] * 6
    assert resolve(None, ["eyes.beta=3"]).build_pose(POSE).beta[3:].tolist() == [3.0] * 6


@pytest.mark.parametrize(
    ("item", "words"),
    [
        ("head.q=1", "rotation filter"),
        ("head.min_cutoff=fast", "expected a number"),
        ("head.min_cutoff=-1", "must be > 0"),
        ("eyes.foo=1", "neither"),
    ],
)
def test_bad_head_settings_are_one_line(item, words):
    with pytest.raises(FacecleanError, match=words):
        resolve("kalman", [item])


def _stepped(cleaner, t, x) -> np.ndarray:
    cleaner.reset()
    return np.array([cleaner.step(xi, ti) for ti, xi in zip(t, x, strict=True)])


def _livelink_take(tmp_path) -> tuple:
    """A small Live Link CSV with moving angles, a yaw across the cut and tracking loss."""
    from faceclean.io.livelink_csv import ANGLES, ORDER, timecode_text

    rng = np.random.default_rng(7)
    lines = [",".join(("Timecode", "BlendshapeCount", *ORDER, *ANGLES))]
    for i in range(90):
        tc = timecode_text(40000.0 + i / 60.0)
        if i in (30, 31):
            lines.append(f"{tc},0")
            continue
        shapes = rng.uniform(0, 1, 52)
        angles = 0.1 * np.sin(i / 9 + np.arange(9)) + rng.normal(0, 0.01, 9)
        angles[0] = wrap(3.1 + 0.01 * i)
        cells = [f"{v:.10f}" for v in (*shapes, *angles)]
        lines.append(",".join((tc, "61", *cells)))
    path = tmp_path / "take.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_clean_cleans_the_angles_streamed_as_in_memory(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(stream, "BLOCK", 7)  # block boundaries inside the take
    src = _livelink_take(tmp_path)
    out = tmp_path / "out.csv"
    assert main(["clean", str(src), "-o", str(out), "--method", "one-euro"]) == 0
    assert "9 head/eye angles with rotation (tuned preset)" in capsys.readouterr().out
    raw, got = io.load(src), io.load(out)
    # in memory: the same cleaners through Animation and the Live Link writer
    choice = resolve("one-euro")
    mem = clean_pose(choice.build(raw.names).clean(raw), choice.build_pose)
    ref = tmp_path / "mem.csv"
    io.save(mem, ref)
    assert out.read_bytes() == ref.read_bytes()
    moved = np.abs(got.meta["pose"] - raw.meta["pose"])
    assert np.nanmax(moved) > 1e-3 and np.nanmax(moved[:, 0]) < 0.05  # yaw: the short way
    assert np.isnan(got.meta["pose"][30:32]).all()  # tracking loss stays missing
    lines = src.read_bytes().split(b"\n")
    assert out.read_bytes().split(b"\n")[31:33] == lines[31:33]
    # Cleaner.clean (the library facade) does the same to the angles
    np.testing.assert_array_equal(
        Cleaner.load("one-euro").clean(raw).meta["pose"], mem.meta["pose"]
    )


def test_set_head_changes_only_the_head(tmp_path):
    src = _livelink_take(tmp_path)
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["clean", str(src), "-o", str(a), "--method", "ema"]) == 0
    argv = ["clean", str(src), "-o", str(b), "--method", "ema", "--set", "head.min_cutoff=0.3"]
    assert main(argv) == 0
    pa, pb = io.load(a).meta["pose"], io.load(b).meta["pose"]
    assert np.nanmax(np.abs(pa[:, :3] - pb[:, :3])) > 1e-3
    np.testing.assert_array_equal(pa[:, 3:], pb[:, 3:])
    np.testing.assert_array_equal(io.load(a).values, io.load(b).values)


def test_info_says_the_angles_are_cleaned(tmp_path, capsys):
    assert main(["info", str(_livelink_take(tmp_path))]) == 0
    out = capsys.readouterr().out
    assert "passthrough" not in out
    assert "9 head/eye angles (rad): HeadYaw" in out and "rotation filter" in out


@needs_takes
def test_a_real_head_take_is_smoother_and_still_follows(tmp_path):
    raw = io.load(HEAD_TAKE)
    out = Cleaner.load("one-euro").clean(raw)
    p, q = raw.meta["pose"][:, :3], out.meta["pose"][:, :3]
    jitter = (np.diff(q, 2, axis=0) ** 2).mean() / (np.diff(p, 2, axis=0) ** 2).mean()
    assert jitter < 0.8  # smoother
    assert np.abs(q - p).max() < np.radians(2.0)  # and close: no lag of a whole turn


def test_rotation_rows_in_a_plain_animation():
    """``clean_pose`` leaves a take without angles as it was."""
    a = Animation(np.arange(3) / 60, np.zeros((3, 1)), ["jawOpen"])
    assert clean_pose(a, resolve().build_pose) is a
