"""A face's own rest reading in the tracker map (learned/tracker_map.py
``set_rest_reading``, from a guided calibration): the named outputs measure a rise from
min(r, reading), the others keep the stream's rest, in every path of the runtime."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.animation import Animation
from faceclean.filters import compiled
from faceclean.learned.formats import TRACKER_MAP
from faceclean.learned.tracker_map import MapWeights, TrackerMap

NAMES = ("mouthSmileLeft", "jawOpen", "cheekSquintLeft")
READING = {"mouthSmileLeft": 0.05}  # the face's smile reading at rest
OUTPUTS = ("mouthSmileLeft", "cheekSquintLeft")  # the jaw keeps the stream's rest


def weights(band: float = 0.0, noise: float = 0.0) -> MapWeights:
    k = len(NAMES)
    # y = B (u - r): the smile's rise moves the cheek and, through a habit, the jaw
    b = np.array([[1.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.4, 0.0, 1.0]])
    arrays = {"min_cutoff": np.full(k, 1.5), "beta": np.full(k, 0.5),
              "d_cutoff": np.full(k, 1.0), "mu": np.zeros(2 * k), "sd": np.ones(2 * k),
              "w1": np.zeros((0, 2 * k)), "b1": np.zeros(0), "w2": np.zeros((k, 0)),
              "b2": np.zeros(k), "a": np.zeros((k, k)), "b": b, "c": np.zeros(k)}  # fmt: skip
    config = {"format": TRACKER_MAP, "inputs": list(NAMES), "outputs": list(NAMES),
              "hidden": 0, "prefilter": True, "rest": True, "deadband": band,
              "noise_band": noise, "rest_tau": [0.1, 0.1, 0.1],
              "rest_warm": [0.1, 0.1, 0.1]}  # fmt: skip
    return MapWeights.build(config, arrays)


def held(level: float, n: int = 150, fps: float = 30.0) -> Animation:
    """A face holding its smile at ``level`` from the first frame, then letting it go to
    the face's rest (0.05) at 3 s; the jaw and cheek at rest; a little noise."""
    rng = np.random.default_rng(2)
    t = np.arange(n) / fps
    x = np.column_stack([np.where(t < 3.0, level, 0.05), np.full(n, 0.02), np.full(n, 0.03)])
    return Animation(t, np.clip(x + rng.normal(0, 0.002, x.shape), 0, 1), NAMES)


def cleaned(anim: Animation, reading=READING, outputs=OUTPUTS, **kw) -> np.ndarray:
    tm = TrackerMap(weights=weights(**kw), names=anim.names)
    tm.set_rest_reading(reading, outputs)
    return tm.clean(anim).values


def test_a_smile_held_from_the_first_frame_reads_as_held_with_the_faces_rest_reading():
    anim = held(0.35)
    t = anim.times
    alone, read = cleaned(anim, None), cleaned(anim)
    early = (t > 1.0) & (t < 3.0)
    assert np.abs(alone[early, 0]).max() < 0.02  # the stream's rest is the held smile: 0
    assert read[early, 0] == pytest.approx(0.30, abs=0.02)  # 0.35 above the face's 0.05
    assert read[early, 2] == pytest.approx(0.4 * 0.30, abs=0.02)  # the cheek with it
    # the jaw, not named: unchanged (the reading steps the take, the plain map may run it
    # whole: the same sums in another order)
    np.testing.assert_allclose(read[:, 1], alone[:, 1], rtol=0, atol=1e-12)
    late = t > 4.0  # let go: the stream found the face's rest, the reading adds nothing
    assert np.abs(read[late] - alone[late]).max() < 0.01


def test_a_face_that_reads_below_its_reading_is_cleaned_as_without_it():
    anim = held(0.0)  # a smile reading under 0.05 throughout: r < reading
    anim = anim.with_values(np.clip(anim.values - [0.06, 0, 0], 0, 1))
    np.testing.assert_allclose(cleaned(anim), cleaned(anim, None), rtol=0, atol=1e-12)


def test_no_reading_and_readings_of_other_channels_leave_the_map_alone():
    anim = held(0.35)
    alone = cleaned(anim, None)
    for reading, outputs in (({}, OUTPUTS), (READING, ()), ({"browInnerUp": 0.1}, OUTPUTS)):
        assert np.array_equal(cleaned(anim, reading, outputs), alone)
    tm = TrackerMap(weights=weights(), names=NAMES)
    tm.set_rest_reading(READING, OUTPUTS)
    tm.set_rest_reading(None)  # taken back
    assert np.array_equal(tm.clean(anim).values, alone)


@pytest.mark.parametrize("band, noise", [(0.0, 0.0), (0.01, 16.0)])
def test_the_usual_frame_path_and_the_whole_take_give_the_stepped_numbers(band, noise,
                                                                         monkeypatch):  # fmt: skip
    monkeypatch.setattr(compiled, "WHOLE_TAKE_FRAMES", 0)
    rng = np.random.default_rng(4)
    n = 160
    dt = rng.uniform(0.01, 0.05, (n, 2))
    dt[100:130] = 1 / 30  # even steps, then uneven again
    t = np.cumsum(dt, axis=0)
    t[60, 1] = t[59, 1] - 0.01  # an old time: that stream holds
    x = np.clip(0.3 + 0.2 * np.sin(t[:, :, None] + np.arange(3)), 0, 1)
    x = x + rng.normal(0, 0.01, x.shape)
    fast, general = (TrackerMap(weights=weights(band, noise), names=NAMES) for _ in range(2))
    for tm in (fast, general):
        tm.set_rest_reading({"mouthSmileLeft": 0.2, "cheekSquintLeft": 0.1}, OUTPUTS)
    general._usual = lambda x, tt: None
    taken = []
    usual = fast._usual
    fast._usual = lambda x, tt: taken.append(usual(x, tt)) or taken[-1]
    for i in range(n):
        np.testing.assert_allclose(fast.step(x[i], t[i]), general.step(x[i], t[i]),
                                   rtol=0, atol=1e-12)  # fmt: skip
    assert sum(o is not None for o in taken) > n * 0.8
    one = Animation(t[:, 0], x[:, 0], NAMES)  # the whole take, compiled, against stepping it
    tm = TrackerMap(weights=weights(band, noise), names=NAMES)
    tm.set_rest_reading(READING, OUTPUTS)
    was = compiled.enabled()
    if not compiled.enable(warm=False):
        pytest.skip("numba not installed: a whole take steps in numpy")
    try:
        whole = tm.clean(one).values
    finally:
        if not was:
            compiled.disable()
    tm.reset()
    stepped = np.array([tm.step(one.values[i], one.times[i]) for i in range(n)])
    np.testing.assert_allclose(whole, stepped, rtol=0, atol=1e-12)
