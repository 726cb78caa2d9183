"""The page's state as CLI words (faceclean.ui.tuning): the preset and levels files it
saves give the cleaner the words give, through the one resolver."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import irregular

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.resolve import resolve
from faceclean.ui.tuning import Tuning, preset_doc


def _take() -> Animation:
    t = irregular(240, seed=3)
    rng = np.random.default_rng(3)
    return Animation.from_arkit(
        t, (0.5 + 0.3 * np.sin(3 * t[:, None]) + rng.normal(0, 0.03, (240, 52))).clip(0, 1)
    )


@pytest.mark.parametrize(
    "words, items",
    [
        ("one-euro", ["eyes.min_cutoff=0.2", "beta=0.5", "jaw.beta=2"]),
        ("kalman", ["q=2", "mouth.r=0.05"]),
        ("ema", ["tau=0.05", "brows.tau=0.2"]),
    ],
)
def test_a_saved_preset_and_levels_clean_as_the_words_do(tmp_path, words, items):
    items = [
        *items,
        "jawOpen.beta=0.1" if words == "one-euro" else "jawOpen.gain=1.3",
        "eyes.gain=1.2",
    ]
    tuning = Tuning(words, tuple(items)).with_choice()
    rest = tuning.save_preset(tmp_path / "p.json")
    tuning.save_levels(tmp_path / "l.json")
    assert all(("gain" in r) or r.startswith("jawOpen.") for r in rest)  # a preset holds groups
    smoothing_rest = [r for r in rest if "gain" not in r]
    from faceclean.adjust import Adjust

    again = Tuning(
        str(tmp_path / "p.json"), tuple(smoothing_rest), Adjust.load(tmp_path / "l.json")
    )
    take = _take()
    a, b = tuning.with_choice().clean(take), again.with_choice().clean(take)
    assert np.allclose(a.values, b.values, atol=1e-12, equal_nan=True)


def test_a_global_key_on_a_tuned_preset_replaces_its_group_values():
    doc, rest = preset_doc("one-euro", ["min_cutoff=0.5"])
    assert doc["params"]["min_cutoff"] == 0.5 and rest == []
    assert all("min_cutoff" not in g for g in doc["groups"].values())
    assert doc["groups"]["eyes"]["beta"] == 12.8  # the rest of the shipped preset stays
    built = resolve("one-euro", ["min_cutoff=0.5"]).build(ARKIT52)
    assert np.all(np.asarray(built.min_cutoff) == 0.5)


def test_refusals_are_the_resolvers():
    with pytest.raises(FacecleanError, match="unknown setting 'min_cutof'"):
        Tuning("one-euro", ("min_cutof=1",)).with_choice()
    with pytest.raises(FacecleanError, match="a preset holds a classical"):
        preset_doc("lstm", [])
    mapped = Tuning(None, ("detail=0.5",), tracker="mediapipe").with_choice()  # not the default
    with pytest.raises(FacecleanError, match="tracker-map: .* give --tracker mediapipe and its"):
        mapped.save_preset("unused.json")
    with pytest.raises(FacecleanError, match="at most 256"):
        Tuning("one-euro", ("beta=1",) * 257).with_choice()
    with pytest.raises(FacecleanError, match="offline"):
        Tuning("gaussian").with_choice().build()
    assert Tuning("gaussian").with_choice().clean(_take()).n_frames == 240  # offline mode: fine


def test_the_mediapipe_map_offers_its_detail_per_channel():
    """--tracker mediapipe: the page's keys are the map's detail (the model's scale on
    every channel) and its rest's drift; a channel's own value shows on that channel and
    cleans as the words do."""
    tuning = Tuning(None, ("jawOpen.detail=1",), tracker="mediapipe").with_choice()
    state = tuning.describe()
    assert state["method"] == "tracker-map" and state["keys"] == ["detail", "rest_drift"]
    drift = state["values"]["rest_drift"]  # the shipped map's: climbing but on the lids
    assert drift[ARKIT52.index("eyeBlinkLeft")] == 0.0 and drift[ARKIT52.index("jawOpen")] > 0
    values = state["values"]["detail"]
    scale = tuning.choice.build(ARKIT52).weights.config["detail_scale"]
    assert values[ARKIT52.index("jawOpen")] == 1.0
    assert values[ARKIT52.index("eyeBlinkLeft")] == scale
    take = _take()
    a = tuning.clean(take).values
    b = Tuning(None, (), tracker="mediapipe").with_choice().clean(take).values
    jaw = ARKIT52.index("jawOpen")
    assert not np.allclose(a[:, jaw], b[:, jaw]) and np.allclose(
        np.delete(a, jaw, axis=1), np.delete(b, jaw, axis=1), equal_nan=True
    )


def test_a_neutral_on_the_page_is_the_calibrate_commands_for_its_cleaner():
    # the Calibrate button: levels for a filter; for the MediaPipe map (--tracker mediapipe)
    # the face's rest reading as the map sees it and no levels, as `calibrate --tracker
    # mediapipe` writes it
    from faceclean.trackers.mediapipe import NAMES

    rng = np.random.default_rng(5)
    x = np.clip(0.1 + rng.normal(0, 0.003, (60, len(NAMES))), 0, 1)
    hold = Animation(np.arange(60) / 30.0, x, NAMES)
    mp = Tuning(tracker="mediapipe").with_choice().neutral(hold, 1.0, "live")
    assert mp.rules == () and mp.facts["levels"] == "none"
    assert mp.adaptation.rest["mouthSmileLeft"] == pytest.approx(0.1, abs=0.01)
    assert "eyeLookDownLeft" in mp.adaptation.rest_outputs
    filt = Tuning("one-euro").with_choice().neutral(hold, 1.0, "live")
    assert filt.adaptation is None and filt.rules
