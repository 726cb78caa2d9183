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
    gain = rng.uniform(1.0, 9.5, 52)  # top = offset + 1 / gain: 0.1 .. 1.0 (MAX_GAIN 10)
    gain[list(BLINK)] = (1.2, 1.6)  # eyelids blink (a rise of at least BLINK_RISE)
    adj = calibrate(_take(gain, offset), rom=True)  # a range of motion: tops map to 1
    lv = adj.levels(ARKIT52)
    np.testing.assert_allclose(lv.offset, offset, atol=0.002)
    np.testing.assert_allclose(lv.gain, gain, rtol=0.03)
    # the observed range maps onto [0, 1]: neutral to 0, the top to 1
    np.testing.assert_allclose(adj.apply(offset, ARKIT52), 0.0, atol=0.01)
    np.testing.assert_allclose(adj.apply(offset + 1.0 / gain, ARKIT52), 1.0, atol=0.03)
    weak = {ARKIT52[i] for i in np.flatnonzero(1.0 / gain + offset < 0.2)}
    assert weak <= set(adj.facts["lifted"]) and weak  # small ranges are lifted, with a ROM


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
    assert main(["calibrate", str(take), "-o", str(calib), "--rom"]) == 0
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
    base = calibrate(_take(gain, offset), rom=True)  # a full calibration: neutral and tops
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


# -- issue 19 section 3: levels stay in range, calibration does not rewrite a performance --


def _iphone_take(seed: int = 0) -> Animation:
    """An iPhone-like take: a neutral second, then small real movements (jawLeft peaks
    at 0.08, tongueOut 0.06, mouthRollUpper 0.09) and full-range blinks and jawOpen."""
    rng = np.random.default_rng(seed)
    n = int(6 * FPS)
    x = np.full((n, 52), 0.02) + rng.normal(0.0, 0.0015, (n, 52))
    for name, peak, start in (
        ("jawLeft", 0.08, 80), ("tongueOut", 0.06, 140), ("mouthRollUpper", 0.09, 200),
        ("jawOpen", 0.7, 260),
    ):  # fmt: skip
        x[:, INDEX[name]] += (peak - 0.02) * _bump(n, start, 8, 20)
    for j, seed_j in zip(BLINK, (1, 2), strict=True):
        x[:, j] = _blinks(n, 0.1, 0.95, 70, seed_j)
    return Animation.from_arkit(np.arange(n) / FPS, np.clip(x, 0, 1))


def test_an_iphone_take_is_not_lifted_without_evidence(tmp_path, capsys):
    take = _iphone_take()
    adj = calibrate(take)  # tracker arkit, no range of motion
    lv = adj.levels(ARKIT52)
    for name in ("jawLeft", "tongueOut", "mouthRollUpper", "jawOpen"):
        assert lv.gain[INDEX[name]] < 1.1, name  # the neutral subtracted, the range kept
        assert name in adj.facts["moved"] and name not in adj.facts["lifted"]
    mapped = adj.apply(take.values, ARKIT52)
    assert 0.05 < mapped[:, INDEX["jawLeft"]].max() < 0.07  # a small movement stays small
    assert mapped[:, list(BLINK)].max() == 1.0  # blinks are evidence: they still close
    # the command says so: nothing above a gain of 2 but the eyelids' blink-aware gain
    path = tmp_path / "take.csv"
    io.save(take, path)
    assert main(["calibrate", str(path), "-o", str(tmp_path / "c.json")]) == 0
    out = capsys.readouterr().out
    assert "0 lifted to their top (tracker arkit)" in out and "jawLeft" not in out
    # the eyelids' gain is said as what it is (review: "0 lifted" read as no gain at all)
    assert "2 eyelids scaled to close (their blinks)" in out
    assert sorted(adj.facts["closed"]) == ["eyeBlinkLeft", "eyeBlinkRight"]


def test_a_range_of_motion_or_a_tracker_profile_lifts_with_a_capped_gain(tmp_path, capsys):
    from faceclean.calibration import MAX_GAIN
    from faceclean.channels import TRACKERS

    take = _iphone_take()
    rom = calibrate(take, rom=True).levels(ARKIT52)
    assert rom.gain[INDEX["jawOpen"]] == pytest.approx(1 / 0.68, rel=0.05)  # top to 1
    assert rom.gain[INDEX["jawLeft"]] == MAX_GAIN  # 1 / 0.06 = 17 is capped
    # a MediaPipe take: its weak channels (eyeWide peaking at 0.04) are lifted, only they
    x = take.values.copy()
    for name in TRACKERS["mediapipe"]:
        x[:, INDEX[name]] += 0.14 * _bump(len(x), 300, 6, 10)  # 0.02 -> 0.16
    mp = Animation(take.times, np.clip(x, 0, 1), take.names)
    adj = calibrate(mp, tracker="mediapipe")
    lv = adj.levels(ARKIT52)
    assert set(adj.facts["lifted"]) == set(TRACKERS["mediapipe"])
    assert lv.gain[INDEX["eyeWideLeft"]] == pytest.approx(1 / 0.14, rel=0.1)
    assert lv.gain[INDEX["jawLeft"]] < 1.1
    # the command prints every channel whose gain exceeds 2, and says what was capped
    path = tmp_path / "take.csv"
    io.save(take, path)
    assert main(["calibrate", str(path), "-o", str(tmp_path / "c.json"), "--rom"]) == 0
    out = capsys.readouterr().out
    high = {ln.split()[0] for ln in out.splitlines()[2:]}
    expect = {ARKIT52[i] for i in np.flatnonzero(Adjust.load(tmp_path / "c.json").levels(
        ARKIT52).gain > 2)}  # fmt: skip
    assert high == expect and {"jawLeft", "tongueOut", "mouthRollUpper"} <= high
    assert "jawLeft              gain 10.00 (capped)" in out
    with pytest.raises(SystemExit):  # argparse: not a known tracker
        main(["calibrate", str(path), "-o", str(tmp_path / "c.json"), "--tracker", "kinect"])


def test_info_counts_channels_and_its_more_adds_up(tmp_path, capsys):
    path = tmp_path / "take.csv"
    io.save(_iphone_take(), path)
    calib = tmp_path / "c.json"
    assert main(["calibrate", str(path), "-o", str(calib)]) == 0
    capsys.readouterr()
    assert main(["info", str(path), "--calibration", str(calib)]) == 0
    out = capsys.readouterr().out
    assert "levels on 52 of 52 channels (52 patterns)" in out and "rules" not in out
    shown = [ln for ln in out.splitlines() if "(1 channel):" in ln]
    more = int(out.split("... and ", 1)[1].split()[0])
    assert len(shown) + more == 52


def test_levels_are_clamped_to_0_1_unless_an_overshoot_is_asked_for(tmp_path):
    x = np.full((4, 52), 0.9)
    gain = Adjust.from_overrides([("eyeBlink*", "gain", 1.2)])
    y = gain.apply(x, ARKIT52)
    assert y[:, BLINK[0]].max() == 1.0  # 1.08 clamped, not passed on
    assert np.array_equal(y[:, INDEX["jawOpen"]], x[:, INDEX["jawOpen"]])  # untouched
    wide = gain.merged(Adjust.from_overrides([("eyeBlink*", "clamp", "0,1.2")]))
    assert wide.apply(x, ARKIT52)[0, BLINK[0]] == pytest.approx(1.08)
    free = gain.merged(Adjust.from_overrides([("eyeBlink*", "clamp", "none")]))
    assert free.apply(np.full(52, 2.0), ARKIT52)[BLINK[0]] == pytest.approx(2.4)
    path = tmp_path / "free.json"
    free.save(path)  # clamp=none round-trips through the file (strict JSON: false)
    assert json.loads(path.read_text())["channels"]["eyeBlink*"]["clamp"] is False
    assert Adjust.load(path).apply(np.full(52, 2.0), ARKIT52)[BLINK[0]] == pytest.approx(2.4)


@pytest.mark.parametrize("fmt", ["csv", "livelink", "json"])  # streamed and whole
def test_a_take_in_percent_is_refused_with_the_fix_then_cleaned_with_scale(tmp_path, capsys, fmt):
    t = np.arange(120) / FPS
    path = tmp_path / ("take.json" if fmt == "json" else "take.csv")
    io.save(Animation(t, np.full((120, 52), 7.5), ARKIT52, {"format": fmt}), path, fmt=fmt)
    out = tmp_path / ("out" + path.suffix)
    assert main(["clean", str(path), "-o", str(out), *ONE_EURO]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--scale 0.01" in err[0] and "percent" in err[0], err
    assert not out.exists()
    assert main(["clean", str(path), "-o", str(out), *ONE_EURO, "--scale", "0.01"]) == 0
    np.testing.assert_allclose(io.load(out).arkit()[0], 0.075, atol=1e-6)
    # a rare glitch in an ordinary take is no reason to refuse it
    x = np.full((120, 52), 0.3)
    x[10, 3] = 50.0
    x[20, 4] = 1e300  # nor one past any weight
    io.save(Animation(t, x, ARKIT52, {"format": fmt}), path, fmt=fmt)
    assert main(["clean", str(path), "-o", str(out), *ONE_EURO]) == 0
    # a take past any weight throughout: once cleaned into a take of empty cells, unsaid
    out.unlink()
    io.save(Animation(t, np.full((120, 52), 1e300), ARKIT52, {"format": fmt}), path, fmt=fmt)
    assert main(["clean", str(path), "-o", str(out), *ONE_EURO]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "reach 1e+300 in 6240 cells: add --scale 1e-300" in err[0], err
    assert not out.exists()
    # ... and with --scale 1 (clean them as they are): it came out as zeros, exit 0
    assert main(["clean", str(path), "-o", str(out), *ONE_EURO, "--scale", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "with --scale 1 in 6240 cells: use --scale 1e-300" in err[0], err
    assert not out.exists()
    assert main(["clean", str(path), "-o", str(out), *ONE_EURO, "--scale", "1e-300"]) == 0
    np.testing.assert_allclose(io.load(out).arkit()[0], 1.0, atol=1e-6)


def test_calibrate_refuses_a_take_in_percent_and_takes_it_with_scale(tmp_path, capsys):
    # calibrate wrote offsets of 3.6 and gains of 0.04 for a take in percent, unsaid
    rng = np.random.default_rng(3)
    t = np.arange(300) / 60.0
    x = np.clip(0.05 + 0.5 * np.abs(np.sin(np.outer(t, 1 + rng.random(52)))), 0, 1)
    take, pct = tmp_path / "take.csv", tmp_path / "pct.csv"
    io.save(Animation(t, x, ARKIT52), take)
    io.save(Animation(t, 100.0 * x, ARKIT52), pct)
    out = tmp_path / "c.json"
    assert main(["calibrate", str(pct), "-o", str(out), "--rom"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "add --scale 0.01" in err[0] and not out.exists(), err
    assert main(["calibrate", str(pct), "-o", str(out), "--rom", "--scale", "0.01"]) == 0
    assert main(["calibrate", str(take), "-o", str(tmp_path / "plain.json"), "--rom"]) == 0
    got, want = (
        Adjust.load(out).levels(ARKIT52),
        Adjust.load(tmp_path / "plain.json").levels(ARKIT52),
    )
    for key in ("gain", "offset", "curve"):
        np.testing.assert_allclose(getattr(got, key), getattr(want, key), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("seconds", ["inf", "1e400", "nan", "0", "-1", "4000"])
def test_a_neutral_hold_out_of_range_is_refused_in_one_line(tmp_path, capsys, seconds):
    # third red team: --neutral inf ran, taking the whole take as the neutral, unsaid
    path = tmp_path / "take.csv"
    io.save(_iphone_take(), path)
    out = tmp_path / "c.json"
    assert main(["calibrate", str(path), "--neutral", seconds, "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "the neutral hold must be > 0 and at most 3600 s" in err and "\n" not in err
    assert not out.exists()


@pytest.mark.parametrize("rom", [False, True])
def test_a_take_whose_times_run_backwards_is_refused_and_nothing_is_replaced(tmp_path, capsys, rom):
    # red team: calibrate took a take whose times ran backwards, wrote "neutral from the
    # first -2.97 s" and replaced the file there; clean and --guided refuse such a take
    take = _iphone_take()
    path = tmp_path / "rev.csv"
    io.save(Animation(take.times[::-1].copy(), take.values, take.names), path)
    out = tmp_path / "c.json"
    out.write_text("{}")
    assert main(["calibrate", str(path), "-o", str(out), *(["--rom"] if rom else [])]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "faceclean: calibration: the take's times do not increase"
    assert out.read_text() == "{}"


def test_a_range_of_motion_inside_its_neutral_hold_is_refused(tmp_path, capsys):
    # red team: --rom --neutral 10 on a 6 s take read the whole range of motion as the
    # neutral and said "52 moved, 50 lifted"
    path = tmp_path / "take.csv"
    take = _iphone_take()
    io.save(take, path)
    span = float(take.times[-1] - take.times[0])
    out = tmp_path / "c.json"
    argv = ["calibrate", str(path), "-o", str(out), "--rom", "--neutral", f"{span + 1:g}"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "the take ends within its neutral hold" in err and "\n" not in err
    assert not out.exists()
    assert main(argv[:-2] + ["--neutral", f"{span / 4:g}"]) == 0  # a hold, then the motion


def test_a_take_all_lost_says_so(tmp_path, capsys):
    # third red team: it said "no ARKit blendshape channels", where it has one
    path = tmp_path / "lost.csv"
    path.write_text("time,jawOpen\n0,\n0.1,\n0.2,\n")
    assert main(["calibrate", str(path), "-o", str(tmp_path / "c.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "faceclean: calibration: every frame of the take is a tracking loss"


def test_a_live_neutral_puts_no_levels_before_a_cleaner_that_reads_the_rest_itself():
    # relay --tracker mediapipe --calibrate-seconds: the MediaPipe map measures this stream's
    # rises from its own rest and was fitted on raw scores, so the measured neutral adds no
    # levels before it (its output is the map's own); a filter gets the levels as before.
    from faceclean.calibration import LiveCalibration
    from faceclean.resolve import resolve, tracker_words

    rng = np.random.default_rng(4)
    t = np.arange(120) / 30.0
    x = np.clip(0.2 + rng.normal(0, 0.01, (120, 52)), 0, 1)  # resting high, then a smile
    x[60:, INDEX["mouthSmileLeft"]] = 0.7
    build = resolve(tracker_words("mediapipe")).build
    live, plain = LiveCalibration(build(ARKIT52), 1.0), build(ARKIT52)
    got = np.array([live.step(x[k], t[k]) for k in range(120)])
    want = np.array([plain.step(x[k], t[k]) for k in range(120)])
    assert live.reads_rest and live.adjust is not None
    assert live.adjust.rules == () and live.adjust.facts["levels"] == "none"
    np.testing.assert_allclose(got, want, atol=1e-12)
    ema = LiveCalibration(filters.make("ema"), 1.0)
    for k in range(60):
        ema.step(x[k], t[k])
    assert not ema.reads_rest
    assert ema.adjust.levels(ARKIT52).offset[INDEX["jawOpen"]] == pytest.approx(0.2, abs=0.01)
