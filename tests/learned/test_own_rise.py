"""Outputs a guided calibration has the tracker map read as their own rise alone
(learned/tracker_map.py ``set_own_rise``, map_weights.own_rise): a habit of the map's other
rows cut, the other outputs as they were, the stream going on, in every path."""

from __future__ import annotations

import numpy as np
import pytest
from test_rest_reading import NAMES, weights

from faceclean.adaptation import Adaptation, attach
from faceclean.animation import Animation
from faceclean.learned.map_weights import own_rise
from faceclean.learned.tracker_map import TrackerMap


def smiling(n: int = 240, fps: float = 30.0) -> Animation:
    """A smile that comes and goes, the jaw still, the cheek a little with it; noise."""
    rng = np.random.default_rng(5)
    t = np.arange(n) / fps
    smile = 0.05 + 0.4 * np.clip(np.sin(2 * np.pi * 0.4 * t), 0, None)
    x = np.column_stack([smile, np.full(n, 0.02), 0.03 + 0.3 * (smile - 0.05)])
    return Animation(t, np.clip(x + rng.normal(0, 0.002, x.shape), 0, 1), NAMES)


@pytest.fixture(params=["numpy", "compiled"])
def path(request):
    """The whole take stepped in numpy, or compiled (filters/compiled.py, as a long take
    runs): the compiled take kept the map's rows it first ran with after set_own_rise."""
    from faceclean.filters import compiled

    was = compiled.enabled()
    if request.param == "compiled" and not compiled.enable():
        pytest.skip("numba not installed")
    if request.param == "numpy":
        compiled.disable()
    yield request.param
    (compiled.enable if was else compiled.disable)()


def test_an_output_read_as_its_own_rise_drops_the_map_s_habit_and_nothing_else(path):
    anim = smiling()
    tm = TrackerMap(weights=weights(), names=NAMES)
    plain = tm.clean(anim).values
    tm.set_own_rise(("jawOpen",))
    own = tm.clean(anim).values
    assert plain[:, 1].max() > 0.15  # the map's jaw reads the smile (0.5 x its rise)
    assert np.abs(own[:, 1]).max() < 0.01  # its own input is still: so is it now
    np.testing.assert_array_equal(own[:, [0, 2]], plain[:, [0, 2]])  # the others as they were
    tm.set_own_rise(())
    np.testing.assert_array_equal(tm.clean(anim).values, plain)  # the map's rows again
    # the weights' rows: the own input's rise at gain 1, no other input, no level
    w = own_rise(weights(), ("jawOpen",))
    assert w.arrays["b"][1].tolist() == [0.0, 1.0, 0.0] and w.arrays["c"][1] == 0.0
    assert own_rise(weights(), ("noseSneerLeft",)) is not None  # a name it lacks: unchanged
    np.testing.assert_array_equal(own_rise(weights(), ("noseSneerLeft",)).arrays["b"],
                                  weights().arrays["b"])  # fmt: skip


@pytest.mark.parametrize("band", [0.0, 0.02])
def test_the_step_and_the_whole_take_agree_and_a_stream_goes_on_through_the_change(band):
    anim = smiling()
    tm = TrackerMap(weights=weights(band=band), names=NAMES)
    tm.set_own_rise(("jawOpen",))
    whole = tm.clean(anim).values
    tm.reset()
    stepped = np.array([tm.step(anim.values[i], anim.times[i]) for i in range(anim.n_frames)])
    np.testing.assert_allclose(stepped, whole, rtol=0, atol=1e-12)
    # changed between frames: the rest and the filter carry on (no warm-up again)
    live = TrackerMap(weights=weights(band=band), names=NAMES)
    half = anim.n_frames // 2
    for i in range(half):
        live.step(anim.values[i], anim.times[i])
    live.set_own_rise(("jawOpen",))
    after = np.array([live.step(anim.values[i], anim.times[i])
                      for i in range(half, anim.n_frames)])  # fmt: skip
    np.testing.assert_allclose(after[:, 1], stepped[half:, 1], rtol=0, atol=0.03 if band else 1e-12)


def test_the_adaptation_carries_its_own_rise_outputs_to_the_map():
    ad = Adaptation({}, {}, "mediapipe", own=("jawOpen",))
    back = Adaptation.from_dict(ad.to_dict())
    assert back.own == ("jawOpen",) and "own" not in Adaptation({}, {}).to_dict()
    anim = smiling()
    tm = TrackerMap(weights=weights(), names=NAMES)
    attach(tm, back)
    assert np.abs(tm.clean(anim).values[:, 1]).max() < 0.01
    attach(tm, Adaptation({}, {}, "mediapipe"))  # another face's calibration: the map's rows
    assert tm.clean(anim).values[:, 1].max() > 0.15
