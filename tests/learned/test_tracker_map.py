"""The tracker map: a learned level map behind a tuned pre-filter, streaming per frame."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.learned.formats import TRACKER_MAP
from faceclean.learned.tracker_map import MapWeights, TrackerMap

NAMES = ("eyeBlinkLeft", "eyeBlinkRight", "jawOpen")


def weights(hidden=4, seed=0, prefilter=True, rest=True, deadband=0.0, lift=None,
            detail=None, top=False, noise=0.0, rest_s=(0.0, 0.0)) -> MapWeights:  # fmt: skip
    rng = np.random.default_rng(seed)
    k = len(NAMES)
    arrays = {
        "min_cutoff": np.full(k, 1.5),
        "beta": np.full(k, 0.5),
        "d_cutoff": np.full(k, 1.0),
        "mu": np.zeros(2 * k),
        "sd": np.ones(2 * k),
        "w1": rng.normal(0, 1, (hidden, 2 * k)),
        "b1": rng.normal(0, 0.1, hidden),
        "w2": rng.normal(0, 0.2, (k, hidden)),
        "b2": np.zeros(k),
        "a": np.eye(k) * 1.3,
        "b": np.eye(k) * 0.2 if rest else np.zeros((k, k)),
        "c": np.full(k, -0.05),
    }
    if lift is not None:  # (gain, knee) on both blinks
        arrays["lift_gain"] = np.array([lift[0], lift[0], 0.0])
        arrays["lift_knee"] = np.array([lift[1], lift[1], 0.0])
    if detail is not None:  # on every output
        arrays["detail"] = np.full(k, float(detail))
    config = {"format": TRACKER_MAP, "inputs": list(NAMES), "outputs": list(NAMES),
              "hidden": hidden, "prefilter": prefilter, "rest": rest,
              "deadband": deadband, "lift_top": top, "noise_band": noise,
              "rest_tau": rest_s[0], "rest_warm": rest_s[1],
              "rest_drift": rest_s[2] if len(rest_s) > 2 else 0.0}  # fmt: skip
    return MapWeights.build(config, arrays)


def take(n=120, fps=30.0, seed=1) -> Animation:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fps
    x = (
        0.3
        + 0.2 * np.sin(2 * np.pi * 0.7 * t[:, None] + np.arange(3))
        + rng.normal(0, 0.02, (n, 3))
    )
    return Animation(t, np.clip(x, 0, 1), NAMES)


def test_clean_equals_stepping_and_streams_together():
    a = take()
    tm = TrackerMap(weights=weights())
    cleaned = tm.clean(a).values
    tm.reset()
    stepped = np.array([tm.step(a.values[i], a.times[i]) for i in range(a.n_frames)])
    np.testing.assert_allclose(cleaned, stepped, atol=1e-12)
    tm.reset()  # two streams stepped together give each stream's own result
    both = np.array([tm.step(np.stack([a.values[i]] * 2), np.array([a.times[i]] * 2))
                     for i in range(a.n_frames)])  # fmt: skip
    np.testing.assert_allclose(both[:, 1], stepped, atol=1e-12)


def test_a_still_face_stays_still():
    t = np.arange(300) / 30.0
    x = np.tile([0.12, 0.1, 0.05], (300, 1))
    y = TrackerMap(weights=weights()).clean(Animation(t, x, NAMES)).values
    assert np.ptp(y[5:], axis=0).max() < 1e-9  # constant in, constant out: no invented motion
    assert np.all((y >= 0) & (y <= 1))


def test_levels_change_where_a_filter_cannot():
    a = take()
    y = TrackerMap(weights=weights(hidden=0, prefilter=False, rest=False)).clean(a).values
    np.testing.assert_allclose(y, np.clip(1.3 * a.values - 0.05, 0, 1), atol=1e-12)


def test_missing_frames_hold_and_unknown_columns_pass_through():
    a = take(20)
    names = (*NAMES, "HeadYaw")
    values = np.concatenate([a.values, np.linspace(0, 1, 20)[:, None]], axis=1)
    values[10] = np.nan
    out = TrackerMap(weights=weights()).clean(Animation(a.times, values, names)).values
    assert np.isnan(out[10]).all()  # a missing frame stays missing in a clip
    np.testing.assert_array_equal(
        out[:, 3][~np.isnan(out[:, 3])], values[:, 3][~np.isnan(values[:, 3])]
    )
    tm = TrackerMap(weights=weights(), names=names)
    y9 = [tm.step(values[i], a.times[i]) for i in range(10)][-1]
    np.testing.assert_array_equal(tm.step(values[10], a.times[10]), y9)  # stepped: held


def test_a_checkpoint_round_trips_and_bad_ones_are_refused(tmp_path):
    w = weights()
    path = tmp_path / "m.npz"
    w.save(path)
    a = take()
    np.testing.assert_array_equal(
        TrackerMap(model=path).clean(a).values, TrackerMap(weights=w).clean(a).values
    )
    bad = dict(w.arrays)
    bad["w1"] = bad["w1"][:, :2]
    with pytest.raises(FacecleanError, match="w1"):
        MapWeights.build(w.config, bad)
    with pytest.raises(FacecleanError, match="repeat"):
        MapWeights.build({**w.config, "inputs": ["jawOpen"] * 3}, w.arrays)
    nan = dict(w.arrays, c=np.array([np.nan, 0, 0]))
    with pytest.raises(FacecleanError, match="not finite"):
        MapWeights.build(w.config, nan)


def test_old_times_and_lost_channels_follow_the_time_rules():
    a = take(40)
    names = (*NAMES, "tongueOut")  # a column the model does not know
    x = np.concatenate([a.values, np.linspace(0, 1, 40)[:, None]], axis=1)
    tm = TrackerMap(weights=weights(), names=names)
    y = [tm.step(x[i], a.times[i]) for i in range(20)]
    np.testing.assert_array_equal(tm.step(x[20], a.times[10]), y[-1])  # an older time: held
    np.testing.assert_array_equal(tm.step(x[20], np.nan), y[-1])  # no time: held
    part = x[21].copy()
    part[[0, 3]] = np.nan, np.inf
    out = tm.step(part, a.times[21])
    assert np.isfinite(out).all() and out[3] == y[-1][3]  # a lost cell takes its last output


def test_the_inline_pre_filter_is_one_euro():
    from faceclean.filters.one_euro import OneEuro

    a = take(200)
    t = a.times.copy()
    t[50:] += 1.0  # a gap: both restart
    t[80] = t[79]  # a duplicate: both hold
    anim = Animation(t, a.values, NAMES)
    w = weights(hidden=0, rest=False)
    w.arrays["a"], w.arrays["c"] = np.eye(3), np.zeros(3)  # y = u
    got = TrackerMap(weights=w).clean(anim).values
    want = OneEuro(names=NAMES, min_cutoff=1.5, beta=0.5, d_cutoff=1.0).clean(anim).values
    np.testing.assert_allclose(got, np.clip(want, 0, 1), atol=1e-12)


@pytest.mark.parametrize(
    "band, lift, detail, top, noise, rest_s",
    [
        (0.0, None, None, False, 0.0, (0, 0)),
        (0.05, None, None, False, 0.0, (0, 0)),
        (0.05, (2.5, 0.2), 0.6, False, 0.0, (0, 0)),
        (0.02, (6.0, 0.1), 0.3, True, 0.0, (0, 0)),
        (0.01, None, 0.3, False, 16.0, (0.15, 0.2)),
        (0.0, (2.5, 0.2), None, False, 8.0, (0, 0.3)),
        (0.0, None, None, False, 0.0, (0.3, 0)),
        (0.01, None, 0.3, False, 16.0, ([0.15, 0.0, 0.3], [0.2, 0.0, 0.1])),
        (0.01, None, 0.3, False, 16.0, (0.15, 0.2, 0.05)),
        (0.0, None, None, False, 0.0, (0, 0, 0.3)),
        (0.01, (2.5, 0.2), 0.3, True, 16.0, ([0.15, 0.0, 0.3], [0.2, 0.0, 0.1], [0.0, 0.1, 0.02])),
    ],
)
@pytest.mark.parametrize("names", [NAMES, ("jawOpen", "headYaw", "eyeBlinkLeft")])
def test_the_usual_frame_path_gives_the_general_paths_numbers(names, band, lift, detail, top,
                                                               noise, rest_s):  # fmt: skip
    """``_usual`` (every stream present and advancing) against the general path, forced, on
    streams with uneven steps, then even ones (one step for every stream, the rest's
    factor kept), a lost frame, an old time, a gap and passthrough columns; three streams
    together and one alone."""
    rng = np.random.default_rng(5)
    n = 150
    dt = rng.uniform(0.01, 0.05, (n, 3))
    dt[110:130] = 1 / 30  # even steps, then uneven again
    t = np.cumsum(dt, axis=0)
    t[60, 1] = t[59, 1] - 0.01  # an old time: that stream holds
    t[90:, 2] += 1.0  # a gap: that stream restarts
    t[100:, 0] += 1.0  # ... and the one stream stepped alone
    x = rng.uniform(0, 1, (n, 3, len(names)))
    x[40, 0] = np.nan  # a lost frame
    w = weights(hidden=0, deadband=band, lift=lift, detail=detail, top=top, noise=noise,
                rest_s=rest_s)  # fmt: skip
    for streams in (slice(None), 0):
        fast, general = TrackerMap(weights=w, names=names), TrackerMap(weights=w, names=names)
        general._usual = lambda x, tt: None
        usual, taken = fast._usual, []

        def counted(x, tt, usual=usual, taken=taken):
            out = usual(x, tt)
            taken.append(out is not None)
            return out

        fast._usual = counted
        for i in range(n):
            got = fast.step(x[i, streams], t[i, streams])
            np.testing.assert_allclose(got, general.step(x[i, streams], t[i, streams]),
                                       rtol=0, atol=1e-12)  # fmt: skip
        assert sum(taken) > n * 0.8 and not all(taken)  # both paths ran


def test_the_deadband_holds_tracker_noise_and_passes_movement():
    """y = m - clip(m - y_prev, -eps, eps): noise within eps moves nothing; a movement
    arrives at most eps behind (and a start takes the map's value)."""
    rng = np.random.default_rng(3)
    t = np.arange(300) / 30.0
    still = np.tile([0.3, 0.2, 0.1], (300, 1)) + rng.normal(0, 0.003, (300, 3))
    plain = weights(hidden=0, prefilter=False, rest=False)
    banded = weights(hidden=0, prefilter=False, rest=False, deadband=0.02)
    m = TrackerMap(weights=plain).clean(Animation(t, still, NAMES)).values
    y = TrackerMap(weights=banded).clean(Animation(t, still, NAMES)).values
    np.testing.assert_array_equal(y[0], m[0])
    assert np.abs(np.diff(y, axis=0)).mean() < 0.05 * np.abs(np.diff(m, axis=0)).mean()
    assert np.abs(y - m).max() <= 0.02 + 1e-12
    ramp = np.tile(np.linspace(0, 0.7, 300)[:, None], (1, 3))
    m = TrackerMap(weights=plain).clean(Animation(t, ramp, NAMES)).values
    y = TrackerMap(weights=banded).clean(Animation(t, ramp, NAMES)).values
    moving = np.abs(np.diff(m, axis=0)) > 0
    assert moving.mean() > 0.5 and (np.diff(y, axis=0)[moving] > 0).mean() > 0.9  # it follows
    assert np.abs(y - m).max() <= 0.02 + 1e-12
    per = MapWeights.build({**plain.config, "deadband": [0.02, 0.0, 0.02]}, plain.arrays)
    y = TrackerMap(weights=per).clean(Animation(t, still, NAMES)).values
    m = TrackerMap(weights=plain).clean(Animation(t, still, NAMES)).values
    np.testing.assert_array_equal(y[:, 1], m[:, 1])  # a band of 0: that output untouched
    assert np.abs(np.diff(y[:, 0])).mean() < 0.05 * np.abs(np.diff(m[:, 0])).mean()
    for bad in (-0.1, 0.5, [0.01, 0.02], "x"):
        with pytest.raises(FacecleanError, match="deadband"):
            MapWeights.build({**plain.config, "deadband": bad}, plain.arrays)


def test_the_noise_band_widens_on_a_noisy_face_and_stays_the_floor_on_a_clean_one():
    """learned/band.py: eps = max(floor, c s), s the running mean |second difference| of
    the map: a noisy still face is held far stiller than by the floor alone; a smooth
    movement gets the floor's output; the whole take compiled equals stepping; a restart
    keeps the noise level; a bad c is refused."""
    from faceclean.filters import compiled
    from faceclean.learned import band

    rng = np.random.default_rng(4)
    t = np.arange(600) / 30.0
    noisy = np.tile([0.3, 0.2, 0.1], (600, 1)) + rng.normal(0, 0.02, (600, 3))
    floor = weights(hidden=0, prefilter=False, rest=False, deadband=0.01)
    wide = weights(hidden=0, prefilter=False, rest=False, deadband=0.01, noise=16.0)
    m = TrackerMap(weights=floor).clean(Animation(t, noisy, NAMES)).values
    y = TrackerMap(weights=wide).clean(Animation(t, noisy, NAMES)).values
    assert np.abs(np.diff(y[60:], axis=0)).mean() < 0.3 * np.abs(np.diff(m[60:], axis=0)).mean()
    smooth = 0.4 + 0.2 * np.sin(2 * np.pi * 0.5 * t[:, None] + np.arange(3))
    m = TrackerMap(weights=floor).clean(Animation(t, smooth, NAMES)).values
    y = TrackerMap(weights=wide).clean(Animation(t, smooth, NAMES)).values
    np.testing.assert_allclose(y, m, rtol=0, atol=1e-12)  # c s stays under the floor
    gap = t + (t >= 10.0) * 2.0  # a gap restarts the stream; the noise level is kept
    anim = Animation(gap, noisy, NAMES)
    tm = TrackerMap(weights=wide)
    stepped = np.array([tm.step(noisy[i], gap[i]) for i in range(len(t))])
    assert tm._noise.s.min() > 0.01
    was = compiled.enabled()
    compiled.enable()
    try:
        np.testing.assert_allclose(TrackerMap(weights=wide).clean(anim).values, stepped,
                                   rtol=0, atol=1e-12)  # fmt: skip
        fast = band.whole(noisy, t, np.full(3, 0.01), 16.0)  # the fits' view, compiled
        compiled.disable()  # ... and without numba: the usual frame's step in turn
        np.testing.assert_allclose(band.whole(noisy, t, np.full(3, 0.01), 16.0), fast,
                                   rtol=0, atol=1e-12)  # fmt: skip
    finally:
        compiled.disable()
        if was:
            compiled.enable()
    for bad in (-1.0, 101.0, True, "2"):
        with pytest.raises(FacecleanError, match="noise_band"):
            MapWeights.build({**floor.config, "noise_band": bad}, floor.arrays)


def low_pass(x: np.ndarray, t: np.ndarray, hz: float) -> np.ndarray:
    """The lift's low-pass of x (F, L), written out: p += h / (h + tau) (x - p)."""
    p, tau = x.copy(), 1 / (2 * np.pi * hz)
    for n in range(1, len(x)):
        h = t[n] - t[n - 1]
        p[n] = p[n - 1] + h / (h + tau) * (x[n] - p[n - 1])
    return p


def test_the_lift_closes_a_blink_and_leaves_a_face_at_rest():
    """m_j = max(m_j, clip(g (p_j - r_j - k), 0, 1)) on the blinks, p the raw input
    low-passed: an under-read closure reaches its gain's height, a blip of two frames less;
    below the knee (a face at rest, a half-closed eye) the map's output is untouched;
    jawOpen is not lifted."""
    t = np.arange(150) / 30.0
    x = np.tile([0.1, 0.1, 0.3], (150, 1))
    x[60:62, :2], x[62:92, :2], x[92:94, :2] = 0.25, 0.4, 0.25  # an under-read closure
    x[120:122, :2] = 0.4  # a blip: the low-pass takes it to 0.4 - 0.3 (1 - a)^2 (a = 0.45)
    x[90:96, 2] = 0.9
    plain = weights(hidden=0, prefilter=False, rest=True)
    lifted = weights(hidden=0, prefilter=False, rest=True, lift=(4.0, 0.1))
    m = TrackerMap(weights=plain).clean(Animation(t, x, NAMES)).values
    y = TrackerMap(weights=lifted).clean(Animation(t, x, NAMES)).values
    np.testing.assert_allclose(y[:, :2].max(axis=0), 0.8, atol=1e-6)  # 4 (0.4 - 0.1 - 0.1)
    want = 4 * (low_pass(x[:, :2], t, 4.0) - 0.2)  # the default low-pass, 4 Hz
    np.testing.assert_allclose(y[115:, :2], np.maximum(m[115:, :2], want[115:]), atol=1e-12)
    assert 0.5 < y[115:, 0].max() < 0.65
    np.testing.assert_allclose(m[:, :2].max(), 0.53)  # the map alone: 1.3 0.4 + 0.2 0.3 - 0.05
    np.testing.assert_array_equal(y[:60], m[:60])  # at rest: nothing lifted
    np.testing.assert_array_equal(y[:, 2], m[:, 2])  # jawOpen: no lift
    np.testing.assert_array_equal(y >= m - 1e-15, True)  # a lift only raises
    bad = dict(lifted.arrays, lift_gain=np.array([-1.0, 0, 0]))
    with pytest.raises(FacecleanError, match="lift_gain"):
        MapWeights.build(lifted.config, bad)
    bad = dict(lifted.arrays, lift_knee=np.array([0.1, 2.0, 0]))
    with pytest.raises(FacecleanError, match="lift_knee"):
        MapWeights.build(lifted.config, bad)
    other = {**lifted.config, "inputs": ["jawOpen", "mouthClose", "eyeBlinkRight"]}
    with pytest.raises(FacecleanError, match="'eyeBlinkLeft' is lifted but is not an input"):
        MapWeights.build(other, lifted.arrays)


def test_the_detail_takes_the_filters_lag_off_and_leaves_a_still_face_still():
    """m = A u + ... + d (x - u)_own: with A = I and d = 1 the output is the raw input
    (the filter's lag all taken off); with d = 0.5 a ramp lags half as far; constant in,
    constant out; a lost cell adds no detail."""
    t = np.arange(120) / 30.0
    ramp = np.tile(np.linspace(0.1, 0.7, 120)[:, None], (1, 3))
    base = weights(hidden=0, rest=False)
    base.arrays["a"], base.arrays["c"] = np.eye(3), np.zeros(3)
    lag = {}
    for d in (0.0, 0.5, 1.0):
        w = MapWeights.build(base.config, dict(base.arrays, detail=np.full(3, d)))
        y = TrackerMap(weights=w).clean(Animation(t, ramp, NAMES)).values
        lag[d] = np.abs(ramp[60:] - y[60:]).mean()
        if d == 1.0:
            np.testing.assert_allclose(y, ramp, atol=1e-12)
    assert lag[0.0] > 0.01 and abs(lag[0.5] - lag[0.0] / 2) < 0.1 * lag[0.0]
    w = MapWeights.build(base.config, dict(base.arrays, detail=np.full(3, 0.8)))
    still = TrackerMap(weights=w).clean(Animation(t, np.tile([0.2, 0.3, 0.1], (120, 1)), NAMES))
    assert np.ptp(still.values[3:], axis=0).max() < 1e-12
    tm = TrackerMap(weights=w)
    for i in range(30):
        tm.step(ramp[i], t[i])
    frame = ramp[30].copy()
    frame[0] = np.inf  # a lost cell: its input holds, and no detail is added to it
    np.testing.assert_allclose(tm.step(frame, t[30])[0], np.clip(tm._u[0, 0], 0, 1))
    # the user's detail setting scales the model's gains, as its detail_scale does
    half = MapWeights.build({**base.config, "detail_scale": 0.5}, w.arrays)
    a = Animation(t, ramp, NAMES)
    want = TrackerMap(weights=half).clean(a).values
    np.testing.assert_array_equal(TrackerMap(weights=w, detail=0.5).clean(a).values, want)
    assert not np.array_equal(want, TrackerMap(weights=w).clean(a).values)
    for bad in (-0.1, 1.5, True, "x"):
        with pytest.raises(FacecleanError, match="detail must be a number within"):
            TrackerMap(weights=w, detail=bad)
        with pytest.raises(FacecleanError, match="detail_scale must be a number within"):
            MapWeights.build({**base.config, "detail_scale": bad}, w.arrays)
    for bad in (np.full(3, 5.0), np.array([np.nan, 0, 0])):
        with pytest.raises(FacecleanError, match="detail"):
            MapWeights.build(base.config, dict(base.arrays, detail=bad))
    other = {**base.config, "inputs": ["jawOpen", "mouthClose", "eyeBlinkRight"]}
    with pytest.raises(FacecleanError, match="'eyeBlinkLeft' has a detail but is not an input"):
        MapWeights.build(other, dict(base.arrays, detail=np.full(3, 0.5)))


def test_the_detail_setting_is_per_channel_through_the_resolver():
    """``--set detail=X`` and ``--set PATTERN.detail=X`` reach the shipped MediaPipe map:
    0 leaves the filter's lag, the model's scale is the default, a channel's own setting
    changes that channel only; a bad value is one line."""
    from faceclean.resolve import resolve, tracker_words

    words = tracker_words("mediapipe")
    shipped = resolve(words).build(NAMES)
    assert shipped.detail == shipped.weights.config["detail_scale"] > 0
    t = np.arange(90) / 30.0
    x = np.tile([0.1, 0.1, 0.1], (90, 1))
    x[30:, 2] = np.minimum(0.1 + 0.02 * np.arange(60), 0.8)  # the jaw opens
    a = Animation(t, x, NAMES)
    out = {s: resolve(words, [s]).build(NAMES).clean(a).values for s in
           ("detail=0", "detail=1", "jawOpen.detail=1", "eye*.detail=1")}  # fmt: skip
    base = shipped.clean(a).values
    assert not np.array_equal(out["detail=1"][:, 2], out["detail=0"][:, 2])
    np.testing.assert_array_equal(out["jawOpen.detail=1"][:, 2], out["detail=1"][:, 2])
    np.testing.assert_array_equal(out["jawOpen.detail=1"][:, :2], base[:, :2])
    np.testing.assert_array_equal(out["eye*.detail=1"][:, 2], base[:, 2])
    rise = lambda y: np.argmax(y[:, 2] > 0.3)  # noqa: E731 - the frame the jaw passes 0.3
    assert rise(out["detail=1"]) <= rise(base) <= rise(out["detail=0"])
    for bad in ("detail=2", "jawOpen.detail=-1", "detail=x"):
        with pytest.raises(FacecleanError, match="detail"):
            resolve(words, [bad]).build(NAMES)


def test_the_lifts_top_follows_the_streams_largest_lift():
    """lift_top: l / max(1, the largest l so far): an eye that reads higher than the
    training faces' closes to 1 at its fullest blink and its smaller ones scale down with
    it; before any lift past 1 nothing changes; the gain only falls; a face at rest and
    jawOpen are untouched; reset() forgets the top."""
    t = np.arange(150) / 30.0
    x = np.tile([0.1, 0.1, 0.3], (150, 1))
    closure = lambda v: np.array([0.1, (0.1 + v) / 2, *[v] * 6, (0.1 + v) / 2, 0.1])[:, None]  # noqa: E731
    x[40:50, :2] = closure(0.3)  # l ~ 4 (0.2 - 0.1) = 0.4 (p, the low-pass, ~ x held)
    x[70:80, :2] = closure(0.7)  # l ~ 4 (0.6 - 0.1) = 2.0
    x[100:110, :2] = closure(0.5)  # l ~ 1.2
    a = Animation(t, x, NAMES)
    fixed = TrackerMap(weights=weights(hidden=0, prefilter=False, lift=(4.0, 0.1))).clean(a)
    topped = TrackerMap(weights=weights(hidden=0, prefilter=False, lift=(4.0, 0.1), top=True))
    y, f = topped.clean(a).values, fixed.values
    np.testing.assert_array_equal(y[:70], f[:70])  # no lift past 1 yet: the same
    np.testing.assert_allclose(y[70:80, 0].max(), 1.0)  # the fullest blink: closed, no more
    # a smaller one scaled with it: max(the map, l / 2), the map alone m, r the rest level
    m = TrackerMap(weights=weights(hidden=0, prefilter=False)).clean(a).values
    lift = 4.0 * (low_pass(x[:, :2], t, 4.0) - np.minimum.accumulate(x[:, :2]) - 0.1)
    want = np.maximum(m[:, :2], np.clip(lift / np.maximum(np.maximum.accumulate(lift), 1), 0, 1))
    np.testing.assert_allclose(y[:, :2], want, atol=1e-12)
    assert y[100:110, 0].max() < 0.7 and f[100:110, 0].max() == 1.0  # the fixed gain: clipped
    np.testing.assert_array_equal(y <= f + 1e-15, True)  # the gain only falls
    np.testing.assert_array_equal(y[:, 2], f[:, 2])  # jawOpen: no lift
    topped.reset()
    np.testing.assert_array_equal(topped.clean(a).values, y)  # reset: the top forgotten
    with pytest.raises(FacecleanError, match="lift_top must be true or false"):
        MapWeights.build({**topped.weights.config, "lift_top": "yes"}, topped.weights.arrays)


def test_a_smoothed_rest_keeps_a_noisy_still_face_at_rest():
    # a face that does not move, read at 0.3 with noise 0.04 and a first reading of 0.05
    # (MediaPipe's first frame of a face is often low): the running minimum of u finds the
    # first frame and the noise's dips, so the face rises; smoothed over 0.15 s and from
    # 0.2 s on, its rest is the face's own, and a movement still comes through whole
    rng = np.random.default_rng(3)
    t = np.arange(300) / 30.0
    x = np.clip(0.3 + rng.normal(0, 0.04, (300, 3)), 0, 1)
    x[0] = 0.05
    x[200:230] += 0.4  # then a movement, 1 s
    anim = Animation(t, np.clip(x, 0, 1), NAMES)

    def own_rise(rest_s):
        w = weights(hidden=0, rest_s=rest_s)
        w.arrays["a"], w.arrays["b"], w.arrays["c"] = np.zeros((3, 3)), np.eye(3), np.zeros(3)
        return TrackerMap(weights=w).clean(anim).values

    plain, smoothed = own_rise((0.0, 0.0)), own_rise((0.15, 0.2))
    still = slice(15, 200)  # 0.5 s on, before the movement
    assert plain[still].mean() > 0.2  # the first frame's 0.05 is its rest
    assert smoothed[still].mean() < 0.06 < plain[still].mean() / 3
    assert smoothed[:6].max() == 0.0  # the warm-up: no rise before 0.2 s
    assert smoothed[205:230].mean() > 0.3  # the movement (0.4) comes through


def test_a_drifting_rest_forgets_a_dip_and_keeps_a_held_expression():
    # a still face read at 0.3 whose reading dips to 0.1 for half a second (a blink's gaze,
    # a first frame): with the running minimum the face then reads 0.2 up for good; with a
    # rest that climbs back at 0.02 weight/s it is back at rest 10 s later, at 30 fps and
    # at 120 fps alike, while an expression held 3 s keeps all but 0.06 of itself
    def own_rise(rest_s, fps):
        t = np.arange(int(30 * fps)) / fps
        x = np.full((len(t), 3), 0.3)
        x[(t >= 1.0) & (t < 1.5)] = 0.1
        x[(t >= 20.0) & (t < 23.0)] += 0.5  # held 3 s
        w = weights(hidden=0, prefilter=False, rest_s=rest_s)
        w.arrays["a"], w.arrays["b"], w.arrays["c"] = np.zeros((3, 3)), np.eye(3), np.zeros(3)
        return t, TrackerMap(weights=w).clean(Animation(t, x, NAMES)).values

    t, plain = own_rise((0.0, 0.0), 30.0)
    later = (t >= 12.0) & (t < 20.0)
    assert plain[later].min() > 0.19
    for fps in (30.0, 120.0):
        t, drift = own_rise((0.0, 0.0, 0.02), fps)
        assert drift[(t >= 12.0) & (t < 20.0)].max() < 1e-9
        held = drift[(t >= 20.0) & (t < 23.0)]
        assert held.min() >= 0.5 - 0.02 * 3.0 - 1e-9 and held[0].min() > 0.499


def test_the_users_rest_drift_replaces_the_models_per_channel():
    # --set rest_drift=0 keeps a held expression whole (the rest never climbs); one
    # channel's own value changes that channel's input alone; the values are checked
    t = np.arange(600) / 30.0
    x = np.full((600, 3), 0.3)
    x[30:45] = 0.1  # a dip
    a = Animation(t, x, NAMES)
    drifting = weights(hidden=0, prefilter=False, rest_s=(0.0, 0.0, 0.02))
    still = weights(hidden=0, prefilter=False, rest_s=(0.0, 0.0, 0.0))
    for w in (drifting, still):
        w.arrays["a"], w.arrays["b"], w.arrays["c"] = np.zeros((3, 3)), np.eye(3), np.zeros(3)
    off = TrackerMap(weights=drifting, rest_drift=0.0).clean(a).values
    np.testing.assert_array_equal(off, TrackerMap(weights=still).clean(a).values)
    assert off[-1].min() > 0.19  # the dip kept as the rest
    one = TrackerMap(weights=still, rest_drift=[0.02, 0.0, 0.0])
    assert one.rest_drift.tolist() == [0.02, 0.0, 0.0]
    y = one.clean(a).values
    assert y[-1, 0] < 1e-9 and y[-1, 1:].min() > 0.19
    assert TrackerMap(weights=drifting).rest_drift.tolist() == [0.02] * 3  # the model's
    for bad in (-0.1, 1.5, True, "x", [0.1, 0.2]):
        with pytest.raises(FacecleanError, match="rest_drift must be a number within"):
            TrackerMap(weights=still, rest_drift=bad)


@pytest.mark.parametrize("key, value", [
    ("rest_tau", -0.1), ("rest_warm", 11.0), ("rest_tau", True), ("rest_warm", "0.2"),
    ("rest_tau", [0.1, 0.2]), ("rest_warm", [0, 0, -1]), ("rest_drift", 1.5),
    ("rest_drift", [0.0, -0.01, 0.0])])  # fmt: skip
def test_a_rest_out_of_range_is_refused(key, value):
    w = weights(hidden=0)
    with pytest.raises(FacecleanError, match=key):
        MapWeights.build(dict(w.config, **{key: value}), w.arrays)


@pytest.mark.parametrize(
    "rest_s",
    [
        (0.15, 0.2),
        ([0.15, 0.0, 0.3], [0.2, 0.0, 0.1]),
        (0.15, 0.2, 0.05),
        ([0.15, 0.0, 0.3], 0.2, [0, 0.02, 0.1]),
    ],
)
def test_a_smoothed_rest_is_the_same_in_the_step_the_whole_take_and_the_fits_features(rest_s):
    # the fits score map_features.predict on map_features.features (neural/): the runtime's
    # own output, step by step and as a compiled whole take, through a gap (a restart); one
    # rest for every input, or one per input (the second keeps the plain minimum)
    from faceclean.filters import compiled
    from faceclean.neural import map_features

    w = weights(hidden=0, deadband=0.01, detail=0.3, noise=16.0, rest_s=rest_s)
    a = take(n=400, fps=60.0, seed=4)
    (u, r, _, e), t = map_features.features(w, [_Pair(a)])[0][1:], a.times
    stepped = TrackerMap(weights=w)
    got = np.array([stepped.step(a.values[i], a.times[i]) for i in range(a.n_frames)])
    np.testing.assert_allclose(got, map_features.predict(w, u, r, e, t), atol=1e-12)
    was = compiled.enabled()
    if not compiled.enable(warm=False):
        pytest.skip("numba not installed: a whole take steps in numpy")
    try:
        gap = Animation(np.where(a.times > 3.0, a.times + 1.0, a.times), a.values, NAMES)
        tm = TrackerMap(weights=w)
        whole = tm.clean(gap).values
        tm.reset()
        want = np.array([tm.step(gap.values[i], gap.times[i]) for i in range(gap.n_frames)])
        np.testing.assert_allclose(whole, want, atol=1e-12)
    finally:
        if not was:
            compiled.disable()


class _Pair:
    """A pair as map_features reads one: the take, and itself as the truth."""

    def __init__(self, anim: Animation) -> None:
        self.tracked = self.truth = anim


def test_a_column_the_tracker_never_fills_reads_as_an_absent_input_not_the_output_fed_back():
    # A MediaPipe stream whose brow columns are NaN throughout (rule 2: a bad cell) was fed
    # the map's own brow outputs back as its brow inputs, which climbed to 0.99. A bad
    # input holds its filtered value (0 before any): as if the tracker read 0 there.
    from pathlib import Path

    from faceclean.trackers.mediapipe import NAMES

    model = Path(__file__).resolve().parents[2] / "src/faceclean/models/mediapipe.npz"
    rng = np.random.default_rng(3)
    t = np.arange(240) / 30.0
    x = np.clip(0.2 + 0.15 * np.sin(t[:, None] * rng.uniform(1, 6, len(NAMES))), 0, 1)
    brows = [i for i, n in enumerate(NAMES) if n.startswith("brow")]
    zero, gone = x.copy(), x.copy()
    zero[:, brows], gone[:, brows] = 0.0, np.nan
    want = TrackerMap(model=model, names=NAMES).clean(Animation(t, zero, NAMES)).values
    got = TrackerMap(model=model, names=NAMES).clean(Animation(t, gone, NAMES)).values
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # one bad frame in a live column holds it: the take moves by little, and nowhere NaN
    once = x.copy()
    once[100, brows[0]] = np.nan
    held = TrackerMap(model=model, names=NAMES).clean(Animation(t, once, NAMES)).values
    plain = TrackerMap(model=model, names=NAMES).clean(Animation(t, x, NAMES)).values
    assert np.isfinite(held).all() and np.abs(held - plain).max() < 0.05
