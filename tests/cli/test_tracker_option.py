"""``--tracker mediapipe`` selects the cleaner shipped for MediaPipe; the default stays."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from faceclean import io
from faceclean.animation import Animation
from faceclean.learned.map_weights import MapWeights
from faceclean.learned.tracker_map import TrackerMap
from faceclean.settings import MODELS
from faceclean.trackers.mediapipe import NAMES

CLI = [sys.executable, "-m", "faceclean"]


def _mediapipe_csv(path):
    rng = np.random.default_rng(0)
    t = np.arange(90) / 30
    x = np.clip(
        0.2 + 0.1 * np.sin(t[:, None] * 3 + np.arange(51)) + rng.normal(0, 0.02, (90, 51)), 0, 1
    )
    anim = Animation(t, x, NAMES)
    io.save(anim, path, fmt="mediapipe")
    return io.load(path)


def test_tracker_mediapipe_cleans_with_the_shipped_map(tmp_path):
    src = tmp_path / "face.csv"
    anim = _mediapipe_csv(src)
    out = tmp_path / "clean.csv"
    r = subprocess.run([*CLI, "clean", str(src), "-o", str(out), "--tracker", "mediapipe"],
                       capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "tracker-map" in r.stdout
    got = io.load(out)
    assert got.meta["format"] == "mediapipe"  # written back as it came
    want = TrackerMap(model=MODELS / "mediapipe.npz", names=anim.names).clean(anim).values
    np.testing.assert_allclose(got.values, want, atol=1e-12)
    default = tmp_path / "default.csv"
    r = subprocess.run(
        [*CLI, "clean", str(src), "-o", str(default)], capture_output=True, text=True
    )
    assert r.returncode == 0 and "tracker-map" not in r.stdout  # iPhone input: unchanged
    assert not np.allclose(io.load(default).values, got.values)


def test_an_explicit_method_wins_and_an_unknown_tracker_is_refused(tmp_path):
    src = tmp_path / "face.csv"
    _mediapipe_csv(src)
    args = ["-o", str(tmp_path / "o.csv"), "--tracker", "mediapipe", "--method", "one-euro"]
    r = subprocess.run([*CLI, "clean", str(src), *args], capture_output=True, text=True)
    assert r.returncode == 0 and "one-euro" in r.stdout
    r = subprocess.run([*CLI, "clean", str(src), "-o", str(tmp_path / "o.csv"), "--tracker", "x"],
                       capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 2 and "invalid choice: 'x'" in r.stderr


def test_a_climbing_rest_forgets_a_dip_so_a_still_face_reads_still():
    # issue 34: a face held still whose reading dipped in its first second (MediaPipe's
    # first frames, a blink's gaze) read as a rise for good under the plain running
    # minimum (rest_drift 0: the dip is the rest; 0.02-0.09 off on rendered faces,
    # docs/MODEL.md). The shipped map's rest climbs back (0.005 weight/s on every input
    # but the lids', which keep the plain minimum: here they never dip), so 25 s on it
    # reads as a face that never dipped.
    rng = np.random.default_rng(1)
    t = np.arange(30 * 30) / 30.0
    still = np.clip(0.15 + rng.normal(0, 0.01, (len(t), 51)), 0, 1)
    dipped = still.copy()
    w = MapWeights.load(MODELS / "mediapipe.npz")
    dip = [NAMES.index(n) for n, rho in zip(w.inputs, w.rest[2], strict=True) if rho > 0]
    assert 0 < len(dip) < len(NAMES)  # the lids' inputs keep the plain minimum
    dipped[np.ix_((t > 0.3) & (t < 0.8), dip)] -= 0.1
    late, soon = t >= 25.0, (t > 2.0) & (t < 3.0)
    off = {}
    for drift in (0.0, None):
        tm = TrackerMap(model=MODELS / "mediapipe.npz", names=NAMES, rest_drift=drift)
        y = [tm.clean(Animation(t, x, NAMES)).values for x in (still, dipped)]
        off[drift] = [np.abs(y[0][w].mean(axis=0) - y[1][w].mean(axis=0)).max()
                      for w in (soon, late)]  # fmt: skip
    assert off[0.0][1] > 0.1  # the plain minimum: the dip is the rest for good
    assert off[None][0] > 0.02  # the shipped map: read as a rise at first,
    assert off[None][1] < 0.012  # then forgotten, within the map's band (0.01)


def test_set_rest_drift_zero_keeps_a_held_expression_whole(tmp_path):
    # the shipped map's climbing rest (0.005 weight/s, as --set rest_drift=0.005 here)
    # takes a held smile off at 0.005 weight/s; --set rest_drift=0 keeps it whole
    t = np.arange(20 * 30) / 30.0
    x = np.full((len(t), 51), 0.1)
    x[(t > 2.0), NAMES.index("mouthSmileLeft")] = 0.8  # held from 2 s to the end
    src = tmp_path / "held.csv"
    io.save(Animation(t, x, NAMES), src, fmt="mediapipe")
    outs = {}
    for words in ((), ("--set", "rest_drift=0"), ("--set", "rest_drift=0.005")):
        out = tmp_path / f"out{len(outs)}.csv"
        r = subprocess.run([*CLI, "clean", str(src), "-o", str(out), "--tracker", "mediapipe",
                            *words], capture_output=True, text=True)  # fmt: skip
        assert r.returncode == 0, r.stderr
        outs[words[1:]] = io.load(out).values[:, NAMES.index("mouthSmileLeft")]
    shipped, kept = outs[()], outs[("rest_drift=0",)]
    np.testing.assert_allclose(shipped, outs[("rest_drift=0.005",)], atol=1e-12)
    assert kept[-1] - shipped[-1] > 0.05  # 18 s held: the climbing rest took some off
    assert np.ptp(kept[-90:]) < 1e-9  # held still, and whole


def _jitter(y: np.ndarray) -> float:
    return float(np.mean(np.diff(y, 2, axis=0) ** 2))


def test_set_noise_band_trades_a_noisy_face_s_jitter_for_lag(tmp_path):
    # a slow smile under MediaPipe-like noise: the band widened further over the stream's
    # noise (--set noise_band=32, the model's 8) holds more of it; 0 is the fixed band
    rng = np.random.default_rng(3)
    t = np.arange(12 * 30) / 30.0
    x = np.full((len(t), 51), 0.1) + rng.normal(0, 0.03, (len(t), 51))
    x[:, NAMES.index("mouthSmileLeft")] += 0.3 * (1 - np.cos(t * 2 * np.pi / 6))
    src = tmp_path / "noisy.csv"
    io.save(Animation(t, np.clip(x, 0, 1), NAMES), src, fmt="mediapipe")
    outs = {}
    for c in (None, "0", "8", "32"):
        out = tmp_path / f"out-{c}.csv"
        words = ["--set", f"noise_band={c}"] if c else []
        r = subprocess.run([*CLI, "clean", str(src), "-o", str(out), "--tracker", "mediapipe",
                            *words], capture_output=True, text=True)  # fmt: skip
        assert r.returncode == 0, r.stderr
        outs[c] = io.load(out).values
    np.testing.assert_allclose(outs[None], outs["8"], atol=1e-12)  # the shipped map's own
    assert _jitter(outs["32"]) < 0.7 * _jitter(outs["8"]) < 0.7 * _jitter(outs["0"])
    step = TrackerMap(weights=MapWeights.load(MODELS / "mediapipe.npz"), names=NAMES,
                      noise_band=32)  # fmt: skip
    step.reset()
    take = io.load(src)
    by_frame = np.array([step.step(v, s) for s, v in zip(take.times, take.values, strict=True)])
    np.testing.assert_allclose(by_frame, outs["32"], atol=1e-9)  # the step as the whole take
    for bad in ("-1", "101", "nan", "1,2"):
        r = subprocess.run([*CLI, "clean", str(src), "-o", str(tmp_path / "bad.csv"),
                            "--tracker", "mediapipe", "--set", f"noise_band={bad}"],
                           capture_output=True, text=True)  # fmt: skip
        assert r.returncode == 2 and r.stderr.count("\n") == 1, (bad, r.stderr)
        assert "noise_band" in r.stderr and not (tmp_path / "bad.csv").exists()


def test_a_channel_group_s_setting_out_of_range_is_said_as_the_user_gave_it(tmp_path):
    src = tmp_path / "t.csv"
    _mediapipe_csv(src)
    for words, said in (("mouth.detail=2", "detail must be a number within [0, 1], not 2 on "),
                        ("mouth.rest_drift=1e308", "not 1e+308 on ")):  # fmt: skip
        argv = ["clean", str(src), "-o", str(tmp_path / "o.csv"), "--tracker", "mediapipe"]
        r = subprocess.run([*CLI, *argv, "--set", words], capture_output=True, text=True)
        assert r.returncode == 2 and said in r.stderr and "array(" not in r.stderr, r.stderr
