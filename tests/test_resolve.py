"""faceclean.resolve: the user's words and --set settings -> one cleaner, everywhere."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean import Cleaner
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, INDEX
from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.filters import presets
from faceclean.resolve import parse_item, parse_value, resolve, split_spec
from faceclean.settings import MODELS


def test_values_parse_one_way():
    assert [parse_value(v) for v in ("true", "Off", "yes", "2", "-1.5e-2", "[1, 2]")] == [
        True,
        False,
        True,
        2,
        -0.015,
        [1, 2],
    ]
    assert parse_value('"on"') == "on" and parse_value("fast") == "fast"
    assert parse_item("jawOpen.min-cutoff=2") == ("jawOpen", "min_cutoff", 2)
    assert parse_item("tongueOut.off") == ("tongueOut", "off", None)
    for bad in ("=1", "beta", ".beta=1"):
        with pytest.raises(FacecleanError):
            parse_item(bad)


def test_inline_spec_keeps_bracketed_commas_together():
    assert split_spec("ema:tau=[0.1, 0.2],eyes.tau=0.05") == (
        "ema",
        ["tau=[0.1, 0.2]", "eyes.tau=0.05"],
    )
    assert split_spec("one-euro") == ("one-euro", [])


def test_words_name_models_presets_and_methods(tmp_path):
    assert resolve().method == "adaptive" and resolve("default").method == "adaptive"
    assert resolve("lstm").method == "lstm"  # models/lstm.npz
    assert resolve(MODELS / "fc.npz").method == "fc"  # told apart by the file's format
    assert resolve("gbt").method == "gbt"
    assert resolve("one-euro").source == "one-euro (tuned preset)"
    assert resolve("savgol").source == "savgol (defaults)" and resolve("savgol").offline
    p = tmp_path / "p.json"
    presets.save(p, "kalman", {"q": 3.0, "r": 0.01})
    assert resolve(str(p)).method == "kalman"
    with pytest.raises(FacecleanError, match="no such model file"):
        resolve(tmp_path / "none.npz")


def _params(cleaner, key):
    return np.broadcast_to(getattr(cleaner, key), (len(ARKIT52),))


def test_set_on_a_tuned_method_keeps_the_rest_of_the_preset():
    tuned = resolve("one-euro").build()
    got = resolve("one-euro", ["min_cutoff=2"]).build()
    assert np.all(_params(got, "min_cutoff") == 2.0)
    np.testing.assert_array_equal(_params(got, "beta"), _params(tuned, "beta"))  # per group
    assert len(set(_params(got, "beta").tolist())) > 1


def test_per_channel_settings_change_exactly_the_named_channels():
    tuned = _params(resolve("one-euro").build(), "min_cutoff")
    got = resolve("one-euro", ["jawOpen.min_cutoff=2.0", "eyeBlink*.beta=0.1"]).build()
    cut, beta = _params(got, "min_cutoff"), _params(got, "beta")
    changed = np.flatnonzero(cut != tuned)
    assert changed.tolist() == [INDEX["jawOpen"]] and cut[INDEX["jawOpen"]] == 2.0
    blinks = [INDEX["eyeBlinkLeft"], INDEX["eyeBlinkRight"]]
    assert np.flatnonzero(beta == 0.1).tolist() == sorted(blinks)
    # a group name scopes too, and the cleaned output differs on those channels only
    t = np.arange(120) / 60.0
    x = 0.5 + 0.1 * np.random.default_rng(0).standard_normal((120, 52))
    anim = Animation(t, x, ARKIT52)
    a = resolve("kalman").build().clean(anim).values
    b = resolve("kalman", ["jaw.r=0.2"]).build().clean(anim).values
    differ = np.flatnonzero(np.any(a != b, axis=0))
    assert [ARKIT52[j] for j in differ] == [n for n in ARKIT52 if n.startswith("jaw")]


def test_unknown_or_misplaced_keys_are_one_line_with_the_valid_ones():
    with pytest.raises(FacecleanError, match="valid: min_cutoff, beta, d_cutoff") as e:
        resolve("one-euro", ["foo=1"])
    assert "\n" not in str(e.value)
    with pytest.raises(FacecleanError, match="not per channel"):
        resolve("lstm", ["jawOpen.max_gap=1"])
    with pytest.raises(FacecleanError, match="names no channel"):
        resolve("one-euro", ["jawOpne.beta=1"])
    with pytest.raises(FacecleanError, match="expected a number"):
        resolve("one-euro", ["jawOpen.beta=fast"])


def test_level_keys_go_to_adjust_before_the_cleaner():
    choice = resolve("ema", ["eyeBlink*.gain=2", "tongueOut.off", "tau=0.05"])
    assert [(p, k) for p, k, _ in choice.levels] == [("eyeBlink*", "gain"), ("tongueOut", "off")]
    t = np.arange(30) / 30.0
    x = np.full((30, 52), 0.25)
    got = Cleaner.load("ema", settings=["eyeBlink*.gain=2", "tongueOut.off"]).clean(
        Animation(t, x, ARKIT52)
    )
    np.testing.assert_allclose(got.values[:, INDEX["eyeBlinkLeft"]], 0.5)
    np.testing.assert_allclose(got.values[:, INDEX["tongueOut"]], 0.0)
    np.testing.assert_allclose(got.values[:, INDEX["jawOpen"]], 0.25)


def test_one_model_keyword(tmp_path):
    a = resolve("lstm", [f"model={MODELS / 'fc.npz'}"])
    assert a.method == "fc"  # model=FILE is the file, whatever the method word said
    with pytest.raises(FacecleanError, match="model=FILE"):
        resolve("one-euro", [f"model={MODELS / 'fc.npz'}"])


def test_cli_help_documents_the_settings(capsys):
    for cmd in ("clean", "relay", "plot", "report"):
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        out = capsys.readouterr().out
        assert "jawOpen.min_cutoff=2.0" in out and "eyeBlink*.gain=1.2" in out, cmd


def test_cli_clean_per_channel_override(tmp_path):
    t = np.arange(240) / 60.0
    x = 0.5 + 0.05 * np.random.default_rng(1).standard_normal((240, 52))
    src = tmp_path / "in.npz"
    from faceclean import io

    io.save(Animation(t, x, ARKIT52), src)
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    assert main(["clean", str(src), "-o", str(a), "--method", "one-euro"]) == 0
    assert (
        main(
            [
                "clean",
                str(src),
                "-o",
                str(b),
                "--method",
                "one-euro",
                "--set",
                "jawOpen.min_cutoff=9",
            ]
        )
        == 0
    )
    va, vb = io.load(a).values, io.load(b).values
    assert np.flatnonzero(np.any(va != vb, axis=0)).tolist() == [INDEX["jawOpen"]]


def test_one_euro_keys_set_the_filter_under_the_default_model():
    # issue 19: "--set min_cutoff=2 on the default says unknown setting" although the
    # default is the tuned One Euro filter in adaptive form
    t = np.arange(240) / 60.0
    rng = np.random.default_rng(3)
    x = np.clip(0.4 + 0.2 * np.sin(3 * t)[:, None] + 0.03 * rng.standard_normal((240, 52)), 0, 1)
    anim = Animation(t, x, ARKIT52)
    keys = ["min_cutoff=2", "beta=3", "d_cutoff=1"]
    default = resolve(None).build(ARKIT52)
    tuned = resolve(None, keys).build(ARKIT52)
    assert np.all(tuned.min_cutoff == 2.0) and np.all(tuned.beta == 3.0)
    ours = tuned.clean(anim).values
    one_euro = resolve("one-euro", keys).build(ARKIT52).clean(anim).values
    assert np.abs(ours - default.clean(anim).values).max() > 1e-3  # the key changed it
    assert np.abs(ours - one_euro).max() < 5e-3  # ... into One Euro with those keys
    eyes = resolve(None, ["eyeBlink*.min_cutoff=9"]).build(ARKIT52)
    assert eyes.min_cutoff[INDEX["eyeBlinkLeft"]] == 9.0
    assert eyes.min_cutoff[INDEX["jawOpen"]] == default.min_cutoff[INDEX["jawOpen"]]
    with pytest.raises(FacecleanError, match="min_cutoff must be > 0"):
        resolve(None, ["min_cutoff=0"])
    with pytest.raises(FacecleanError, match="unknown setting 'min_cutoff'"):
        resolve("lstm", ["min_cutoff=2"])  # the paper's LSTM is no One Euro filter


@pytest.mark.parametrize(
    ("item", "hint"),
    [("tongueOut.of", "'tongueOut.off'"), ("tongueOut.offf", "'tongueOut.off'"), ("of", "'off'")],
)
def test_a_typo_of_off_gets_a_hint(tmp_path, capsys, item, hint):
    # issue 19: "tongueOut.of" said only "expected KEY=VALUE"
    src = tmp_path / "a.csv"
    src.write_bytes(b"time,jawOpen\n0,0.5\n0.1,0.9\n0.2,0.1\n")
    assert main(["clean", str(src), "-o", str(tmp_path / "b.csv"), "--set", item]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"did you mean {hint}?" in err[0], err
    with pytest.raises(FacecleanError, match="did you mean 'min_cutoff'"):
        resolve("one-euro", ["min_cutof=2"])
