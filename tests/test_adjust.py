"""Per-channel level mapping (faceclean.adjust): the equation, matching, the file format."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean.adjust import FORMAT, MAP_KEYS, Adjust, matches
from faceclean.channels import ARKIT52, INDEX
from faceclean.cli import main
from faceclean.errors import FacecleanError


def _values(n: int = 40, seed: int = 0) -> np.ndarray:
    x = np.random.default_rng(seed).uniform(0.0, 1.0, (n, 52))
    x[5] = np.nan  # a missing frame
    x[7, 3] = np.nan  # one missing value
    return x


def test_identity_changes_nothing_bit_for_bit():
    x = _values()
    x[0, 0] = -0.0
    y = Adjust().apply(x, ARKIT52)
    assert y is not x and np.array_equal(y.view(np.uint64), x.view(np.uint64))
    ident = Adjust.from_overrides([("jawOpen", "gain", 1.0), ("jawOpen", "offset", 0.0)])
    assert np.array_equal(ident.apply(x, ARKIT52).view(np.uint64), x.view(np.uint64))


def test_overrides_change_exactly_the_named_channels():
    x = _values()
    a = Adjust.from_overrides(
        [("eyeBlink*", "gain", 1.2), ("TongueOut", "off", None), ("JawOpen", "offset", "0.1")]
    )
    y = a.apply(x, ARKIT52)
    touched = {ARKIT52[j] for j in np.flatnonzero(np.any((x != y) & ~np.isnan(x), axis=0))}
    assert touched == {"eyeBlinkLeft", "eyeBlinkRight", "tongueOut", "jawOpen"}
    j = INDEX["eyeBlinkLeft"]
    np.testing.assert_allclose(y[:, j], np.minimum(1.2 * x[:, j], 1.0))  # clamped: issue 19
    assert np.all(y[~np.isnan(x[:, 51]), 51] == 0.0)
    np.testing.assert_allclose(y[:, INDEX["jawOpen"]], np.maximum(x[:, INDEX["jawOpen"]] - 0.1, 0))
    assert np.array_equal(np.isnan(y), np.isnan(x))  # NaN stays NaN, off included


def test_the_equation_offset_gain_curve_clamp():
    names = ("jawOpen",)
    a = Adjust.from_overrides(
        [("jawOpen", "offset", 0.2), ("jawOpen", "gain", 2.0), ("jawOpen", "curve", 0.5)]
    ).merged(Adjust.from_overrides([("jawOpen", "clamp", [0.0, 1.0])]))
    x = np.array([[0.1], [0.2], [0.325], [0.7]])
    # u = 2 (x - 0.2) = -0.2, 0, 0.25, 1.0; sign(u)|u|^0.5 = -0.447, 0, 0.5, 1; clip [0, 1]
    np.testing.assert_allclose(a.apply(x, names)[:, 0], [0.0, 0.0, 0.5, 1.0])
    assert a.apply(np.array([0.325]), names).shape == (1,)  # one frame (M,)


def test_later_rules_win_and_groups_and_spellings_match():
    a = Adjust.from_overrides([("eyes", "gain", 2.0), ("eyeBlinkLeft", "gain", 3.0)])
    lv = a.levels(("EyeBlink_L", "eyeBlink_R", "jawOpen", "HeadYaw"))
    assert list(lv.gain) == [3.0, 2.0, 1.0, 1.0]
    assert matches("mouth*Left", "MouthSmileLeft") and not matches("mouth*Left", "jawLeft")
    assert matches("headyaw", "HeadYaw")  # a channel that is not ARKit, by its own name


@pytest.mark.parametrize(
    ("item", "words"),
    [
        (("jawOpen", "speed", 1), "valid: gain, offset, curve, clamp, off"),
        (("noSuchChannel*", "gain", 1), "names no channel"),
        (("jawOpen", "gain", "fast"), "expected a number"),
        (("jawOpen", "curve", 0), r"must be in \(0, 100\]"),
        (("jawOpen", "gain", 1e308), "within"),
        (("jawOpen", "offset", -1e4), "within"),
        (("jawOpen", "clamp", [1, 0]), "LO <= HI"),
        (("jawOpen", "gain", float("inf")), "finite"),
    ],
)
def test_bad_overrides_say_what_is_wrong(item, words):
    with pytest.raises(FacecleanError, match=words):
        Adjust.from_overrides([item])


def test_file_round_trip_and_bad_files(tmp_path):
    a = Adjust.from_overrides(
        [("eyeBlink*", "gain", 1.2), ("jawOpen", "clamp", (0, 0.8)), ("tongueOut", "off", True)]
    )
    path = tmp_path / "levels.json"
    a.save(path)
    doc = json.loads(path.read_text())
    assert doc["format"] == "faceclean-adjust/1" and set(doc["channels"]) == {
        "eyeBlink*",
        "jawOpen",
        "tongueOut",
    }
    b = Adjust.load(path)
    x = _values()
    np.testing.assert_array_equal(a.apply(x, ARKIT52), b.apply(x, ARKIT52))
    assert set(MAP_KEYS) == {"gain", "offset", "curve", "clamp", "off"}
    path.write_text('{"format": "faceclean-adjust/1", "channels": {"jawOpen": {"gian": 2}}}')
    with pytest.raises(FacecleanError, match="unknown level key 'gian'"):
        Adjust.load(path)
    path.write_text("[1, 2")
    with pytest.raises(FacecleanError, match="levels.json: not valid JSON"):
        Adjust.load(path)
    with pytest.raises(FacecleanError, match="no such calibration file"):
        Adjust.load(tmp_path / "absent.json")


def test_describe_names_each_pattern():
    a = Adjust.from_overrides([("eyeBlink*", "gain", 1.2), ("tongueOut", "off", None)])
    assert a.describe(ARKIT52) == [
        "eyeBlink* (2 channels): gain 1.2",
        "tongueOut (1 channel): off",
    ]
    assert Adjust().describe() == ["identity (no level mapping)"]


def test_extreme_levels_and_glitch_values_never_warn(recwarn):
    a = Adjust.from_overrides([("jawOpen", "gain", 1e3), ("jawOpen", "curve", 100)])
    x = np.array([[1e6, 0.5], [0.5, 0.5], [np.nan, 0.5]])
    y = a.apply(x, ("jawOpen", "mouthClose"))
    assert y[0, 0] == 1.0 and np.isnan(y[2, 0]) and list(y[:, 1]) == [0.5] * 3
    assert not recwarn.list


@pytest.mark.parametrize(
    "calibration",
    [{"take": 5}, {"frames": "x"}, {"moved": 5}, {"lifted": None}, {"closed": {}},
     {"channels": [1, 2]}, {"channels": {"jawOpen": [1]}}, {"channels": {"jawOpen": {"top": "x"}}},
     {"neutral_s": float("nan")}, {"hold": [0]}, {"rom": "yes"}, [1, 2]],
)  # fmt: skip
def test_a_level_file_with_ill_typed_facts_is_refused_in_one_line(tmp_path, capsys, calibration):
    # red team: info crashed on such files (internal error); clean and relay took them
    from faceclean import strict_json

    path = tmp_path / "c.json"
    doc = {"format": FORMAT, "channels": {"jawOpen": {"gain": 1.5}}, "calibration": calibration}
    path.write_text(strict_json.dumps(doc).replace("NaN", "1e999"))
    take = tmp_path / "t.csv"
    take.write_text("time,jawOpen\n0,0.1\n0.1,0.2\n0.2,0.3\n")
    for args in (["info", str(path)], ["info", str(take), "--calibration", str(path)]):
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"faceclean: {path}") and "\n" not in err, err


@pytest.mark.parametrize("clamp", ["none", None, False, "off"])
def test_info_shows_an_unclamped_channel(tmp_path, capsys, clamp):
    from faceclean import strict_json

    path = tmp_path / "c.json"
    path.write_text(
        strict_json.dumps({"format": FORMAT, "channels": {"jawOpen": {"clamp": clamp}}})
    )
    assert main(["info", str(path)]) == 0
    assert "jawOpen: no clamp" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("keys", "words"),
    [({"gain": "2"}, 'gain: expected a number, got "2"'), ({"offset": True}, "offset"),
     ({"curve": [2]}, "curve"), ({"clamp": "0,1"}, "clamp: expected [LO, HI]"),
     ({"clamp": [0, "1"]}, "clamp"),
     ({"off": "yes"}, "off: expected true or false")],
)  # fmt: skip
def test_a_level_file_takes_json_numbers_not_text(tmp_path, capsys, keys, words):
    # red team: "gain": "2" was read as 2; --set takes text, a file says what it means
    path = tmp_path / "c.json"
    path.write_text(json.dumps({"format": FORMAT, "channels": {"jawOpen": keys}}))
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"jawOpen.{words}" in err and "\n" not in err, err
    assert Adjust.from_overrides([("jawOpen", "gain", "2")]).rules[0][2] == 2.0  # --set
