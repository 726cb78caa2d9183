"""Calibration (faceclean.calibration, `faceclean calibrate`): known gains and offsets are
recovered; blinks still close fully; channels the take never moves keep a safe mapping."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean import filters, io
from faceclean.adjust import Adjust
from faceclean.animation import Animation
from faceclean.calibration import calibrate
from faceclean.channels import ARKIT52, INDEX
from faceclean.cli import main
from faceclean.errors import FacecleanError

FPS = 60.0
ONE_EURO = ("--method", "one-euro")
BLINK = (INDEX["eyeBlinkLeft"], INDEX["eyeBlinkRight"])


def _bump(n: int, start: int, rise: int, hold: int) -> np.ndarray:
    """(n,) 0 -> 1 (smoothstep over ``rise`` frames), held ``hold`` frames, back to 0."""
    z = np.zeros(n)
    s = np.linspace(0.0, 1.0, rise)
    up = s * s * (3 - 2 * s)
    z[start : start + rise] = up
    z[start + rise : start + rise + hold] = 1.0
    z[start + rise + hold : start + 2 * rise + hold] = up[::-1]
    return z


def _take(gain: np.ndarray, offset: np.ndarray, rom: bool = True, seed: int = 0) -> Animation:
    """A neutral hold (1 s) then, with ``rom``, one full-range bump per channel.

    The tracker reports x = offset + z / gain (+ noise) for a true weight z in [0, 1].
    """
    rng = np.random.default_rng(seed)
    per = 40  # frames per channel's bump
    n = int(FPS) + (52 * per if rom else int(FPS))
    z = np.zeros((n, 52))
    if rom:
        for i in range(52):
            z[:, i] = _bump(n, int(FPS) + i * per, 10, 15)
    x = offset + z / gain + rng.normal(0.0, 0.0005, z.shape)
    return Animation.from_arkit(np.arange(n) / FPS, x)


def test_known_gains_and_offsets_are_recovered():
    rng = np.random.default_rng(3)
    offset = rng.uniform(0.0, 0.15, 52)
    gain = rng.uniform(1.0, 25.0, 52)  # top = offset + 1 / gain: 0.04 .. 1.0
    gain[list(BLINK)] = (1.2, 1.6)  # eyelids blink (a rise of at least BLINK_RISE)
    adj = calibrate(_take(gain, offset))
    lv = adj.levels(ARKIT52)
    np.testing.assert_allclose(lv.offset, offset, atol=0.002)
    np.testing.assert_allclose(lv.gain, gain, rtol=0.03)
    # the observed range maps onto [0, 1]: neutral to 0, the top to 1
    np.testing.assert_allclose(adj.apply(offset, ARKIT52), 0.0, atol=0.01)
    np.testing.assert_allclose(adj.apply(offset + 1.0 / gain, ARKIT52), 1.0, atol=0.03)
    weak = {ARKIT52[i] for i in np.flatnonzero(1.0 / gain + offset < 0.2)}
    assert set(adj.facts["lifted"]) == weak and weak  # MediaPipe-style channels are lifted


def test_untouched_channels_keep_a_safe_identity_ish_mapping():
    offset = np.full(52, 0.03)
    adj = calibrate(_take(np.ones(52), offset, rom=False))  # a neutral hold only
    lv = adj.levels(ARKIT52)
    assert adj.facts["moved"] == []
    np.testing.assert_allclose(lv.offset, 0.03, atol=0.002)
    np.testing.assert_allclose(lv.gain, 1.0 / (1.0 - lv.offset))  # 1 still maps to 1
    assert np.all(lv.gain < 1.05)


def _blinks(n: int, rest: float, peak: float, every: int, seed: int) -> np.ndarray:
    """(n,) an eyelid resting at ``rest`` that blinks to ``peak`` every ``every`` frames."""
    x = np.full(n, rest)
    for start in range(30, n - 20, every):
        x += (peak - rest) * _bump(n, start, 4, 2)
    return x + np.random.default_rng(seed).normal(0.0, 0.002, n)


@pytest.mark.parametrize("peak", [0.95, 0.6])  # iPhone-like, and a tracker that under-reads
def test_a_blink_still_closes_fully_after_neutral_calibration(peak):
    n = int(6 * FPS)
    x = np.full((n, 52), 0.02)
    x[:, BLINK[0]] = _blinks(n, 0.2, peak, 70, 1)
    x[:, BLINK[1]] = _blinks(n, 0.2, peak, 70, 2)
    take = Animation.from_arkit(np.arange(n) / FPS, x)
    adj = calibrate(take)  # neutral: the first second, which holds a blink
    lv = adj.levels(ARKIT52)
    np.testing.assert_allclose(lv.offset[list(BLINK)], 0.2, atol=0.01)  # the open eye
    mapped = adj.apply(x, ARKIT52)
    cleaned = filters.make("one-euro", {}, names=ARKIT52).clean(take.with_values(mapped))
    for j in BLINK:
        assert mapped[:, j].max() == 1.0  # the calibrated blinks reach full closure
        assert np.percentile(mapped[: int(FPS), j], 50) < 0.02  # and the open eye reads open
        assert cleaned.values[:, j].max() > 0.9  # ... still after the cleaner


def test_no_blink_in_the_take_still_lets_a_full_closure_through():
    n = int(2 * FPS)
    x = np.full((n, 52), 0.2) + np.random.default_rng(0).normal(0, 0.002, (n, 52))
    adj = calibrate(Animation.from_arkit(np.arange(n) / FPS, x))
    full = np.ones(52)
    assert np.all(adj.apply(full, ARKIT52)[list(BLINK)] == 1.0)


def test_bad_takes_are_refused():
    with pytest.raises(FacecleanError, match="no ARKit"):
        calibrate(Animation(np.arange(10) / FPS, np.zeros((10, 1)), ("HeadYaw",)))
    with pytest.raises(FacecleanError, match="fewer than"):
        calibrate(Animation.from_arkit(np.arange(3) / FPS, np.zeros((3, 52))))


def test_calibrate_command_writes_a_file_clean_and_info_use(tmp_path, capsys):
    rng = np.random.default_rng(5)
    offset, gain = rng.uniform(0.0, 0.1, 52), rng.uniform(1.0, 5.0, 52)
    take = tmp_path / "rom.csv"
    io.save(_take(gain, offset), take, fmt="livelink")
    calib = tmp_path / "calib.json"
    assert main(["calibrate", str(take), "-o", str(calib)]) == 0
    doc = json.loads(calib.read_text())
    assert doc["format"] == "faceclean-adjust/1" and len(doc["channels"]) == 52
    assert "52 channels" in capsys.readouterr().out
    np.testing.assert_allclose(Adjust.load(calib).levels(ARKIT52).gain, gain, rtol=0.05)

    out = tmp_path / "out.csv"
    assert main(["clean", str(take), "-o", str(out), "--calibration", str(calib), *ONE_EURO]) == 0
    cleaned = io.load(out).arkit()[0]
    assert cleaned[: int(FPS)].max() < 0.05  # neutral reads 0 ...
    assert cleaned.max(axis=0).min() > 0.8  # ... and every channel's top reaches near 1

    capsys.readouterr()
    assert main(["info", str(calib)]) == 0
    assert "calibrated from" in capsys.readouterr().out
    assert main(["info", str(take), "--calibration", str(calib)]) == 0
    text = capsys.readouterr().out
    assert "calibration" in text and "after" in text


def test_calibrate_never_writes_over_its_take(tmp_path, capsys):
    take = tmp_path / "take.json"
    io.save(_take(np.ones(52), np.zeros(52), rom=False), take)
    before = take.read_bytes()
    assert main(["calibrate", str(take), "-o", str(take)]) == 2
    assert main(["calibrate", str(take), "-o", str(tmp_path / "calib.csv")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert "is the take itself" in err[0] and "a calibration is a .json file" in err[1]
    assert take.read_bytes() == before and not (tmp_path / "calib.csv").exists()


def test_the_report_shows_the_levels_its_cleaners_saw(tmp_path, capsys):
    from faceclean.report.build import node_modules

    try:
        node_modules()
    except FacecleanError as e:
        pytest.skip(f"no three.js for the report here: {e}")
    take = tmp_path / "take.npz"
    io.save(_take(np.full(52, 2.0), np.full(52, 0.1)), take)
    calib = tmp_path / "calib.json"
    assert main(["calibrate", str(take), "-o", str(calib)]) == 0
    html = tmp_path / "r.html"
    argv = ["report", str(take), "-o", str(html), "--method", "ema"]
    assert main([*argv, "--calibration", str(calib)]) == 0
    text = html.read_text()
    assert "Levels before the cleaner" in text and "levels calibrated" in text
    assert "eyeBlinkLeft (1 channel): offset 0.1" in text and "and 41 more" in text
    assert main(argv) == 0
    assert "Levels before the cleaner" not in html.read_text()


def test_a_live_neutral_on_top_of_a_calibration_file_keeps_its_ranges():
    from faceclean.calibration import LiveCalibration

    rng = np.random.default_rng(8)
    offset, gain = rng.uniform(0.0, 0.1, 52), rng.uniform(1.0, 4.0, 52)
    gain[list(BLINK)] = 1.3
    base = calibrate(_take(gain, offset))  # a full calibration: neutral and tops
    top = offset + 1.0 / gain
    shifted = offset + 0.05  # today the tracker rests a little higher
    overrides = Adjust.from_overrides([("tongueOut", "off", None)])
    live = LiveCalibration(filters.make("ema"), 0.5, base, overrides)
    for i in range(40):
        live.step(shifted, i / 60.0)
    assert live.adjust is not None
    lv = live.adjust.levels(ARKIT52)
    moved = [i for i in range(52) if i not in BLINK and i != INDEX["tongueOut"]]
    np.testing.assert_allclose(lv.offset[moved], shifted[moved], atol=1e-9)
    np.testing.assert_allclose(lv.gain[moved], 1.0 / (top - shifted)[moved], rtol=0.02)
    assert lv.off[INDEX["tongueOut"]] and lv.off.sum() == 1  # the overrides stay on top
    live.reset()  # a new stream measures its own neutral again
    assert live.adjust is None
