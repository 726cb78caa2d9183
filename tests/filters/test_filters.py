"""Each classical cleaner against a hand or textbook computation."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import irregular, steps
from scipy.ndimage import gaussian_filter1d
from scipy.signal import savgol_filter

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.filters import make

NAMES = ("eyeBlinkLeft", "jawOpen", "browInnerUp")


def _signal(t: np.ndarray, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    clean = 0.5 + 0.3 * np.sin(2 * np.pi * np.array([0.5, 1.0, 2.0]) * t[:, None])
    return clean + rng.normal(0, 0.03, (len(t), 3))


def test_one_euro_hand_computation_on_three_frames():
    c = make("one-euro", {"min_cutoff": 1.0, "beta": 0.5, "d_cutoff": 2.0}, names=["jawOpen"])
    t = [0.0, 0.02, 0.05]
    x = [0.2, 0.5, 0.4]
    y0 = c.step(np.array([x[0]]), t[0])[0]
    y1 = c.step(np.array([x[1]]), t[1])[0]
    y2 = c.step(np.array([x[2]]), t[2])[0]

    def a(fc, dt):
        tau = 1 / (2 * np.pi * fc)
        return 1 / (1 + tau / dt)

    assert y0 == 0.2
    dx = (0.5 - 0.2) / 0.02
    edx = a(2.0, 0.02) * dx
    want1 = 0.2 + a(1.0 + 0.5 * abs(edx), 0.02) * (0.5 - 0.2)
    assert y1 == pytest.approx(want1, rel=1e-12)
    dx = (0.4 - want1) / 0.03
    edx = edx + a(2.0, 0.03) * (dx - edx)
    want2 = want1 + a(1.0 + 0.5 * abs(edx), 0.03) * (0.4 - want1)
    assert y2 == pytest.approx(want2, rel=1e-12)


def _kalman_textbook(t, z, q, r):
    """Scalar-channel constant-velocity Kalman filter with 2x2 matrices."""
    xs = np.array([z[0], 0.0])
    p = np.diag([r**2, 1.0])
    out = [z[0]]
    h = np.array([[1.0, 0.0]])
    for k in range(1, len(t)):
        dt = t[k] - t[k - 1]
        f = np.array([[1.0, dt], [0.0, 1.0]])
        qm = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        xs = f @ xs
        p = f @ p @ f.T + qm
        s = h @ p @ h.T + r**2
        k_gain = p @ h.T / s
        xs = xs + (k_gain * (z[k] - h @ xs)).ravel()
        p = (np.eye(2) - k_gain @ h) @ p
        out.append(xs[0])
    return np.array(out)


def test_kalman_equals_textbook_per_channel():
    t = irregular(120, seed=1)
    x = _signal(t, seed=1)
    q = np.array([50.0, 300.0, 2000.0])
    r = np.array([0.01, 0.03, 0.05])
    y = steps(make("kalman", {"q": q, "r": r}, names=NAMES), t, x)
    for j in range(3):
        np.testing.assert_allclose(y[:, j], _kalman_textbook(t, x[:, j], q[j], r[j]), atol=1e-10)


def test_ema_gamma_form_is_per_frame_and_tau_form_is_per_second():
    t = irregular(50, seed=2)
    x = _signal(t, seed=2)
    y = steps(make("ema", {"gamma": 0.3}, names=NAMES), t, x)
    want = [x[0]]
    for n in range(1, 50):
        want.append(0.3 * x[n] + 0.7 * want[-1])  # whatever dt is
    np.testing.assert_allclose(y, np.array(want), rtol=1e-12)

    y = steps(make("ema", {"tau": 0.05}, names=NAMES), t, x)
    want = [x[0]]
    for n in range(1, 50):
        a = 1 - np.exp(-(t[n] - t[n - 1]) / 0.05)
        want.append(a * x[n] + (1 - a) * want[-1])
    np.testing.assert_allclose(y, np.array(want), rtol=1e-12)


def test_per_channel_parameters_equal_separate_cleaners():
    t = irregular(80, seed=3)
    x = _signal(t, seed=3)
    for method, params in [
        ("ema", {"tau": [0.01, 0.05, 0.2]}),
        ("one-euro", {"min_cutoff": [0.5, 2.0, 8.0], "beta": [0.0, 0.3, 3.0]}),
        ("gaussian", {"sigma": [0.01, 0.03, 0.1]}),
    ]:
        y = make(method, params, names=NAMES).clean(Animation(t, x, NAMES)).values
        for j in range(3):
            one = {k: v[j] for k, v in params.items()}
            yj = make(method, one, names=NAMES[j : j + 1]).clean(
                Animation(t, x[:, j : j + 1], NAMES[j : j + 1])
            )
            np.testing.assert_allclose(y[:, j], yj.values[:, 0], rtol=1e-12, err_msg=method)


def test_gaussian_kernel_in_time_on_irregular_times():
    t = irregular(200, seed=4)
    t = np.delete(t, np.arange(60, 70))  # dropped frames
    x = _signal(t, seed=4)
    sigma = 0.04
    y = make("gaussian", {"sigma": sigma}, names=NAMES).clean(Animation(t, x, NAMES)).values
    d = t[None, :] - t[:, None]
    w = np.exp(-0.5 * (d / sigma) ** 2) * (np.abs(d) <= 4 * sigma)
    np.testing.assert_allclose(y, w @ x / w.sum(axis=1, keepdims=True), rtol=1e-10)


def test_gaussian_sigma_frames_is_the_frame_filter_on_a_regular_grid():
    t = np.arange(300) / 60.0
    x = _signal(t, seed=5)
    for s in (1, 5):
        y = make("gaussian", {"sigma_frames": s}, names=NAMES).clean(Animation(t, x, NAMES))
        ref = gaussian_filter1d(x, s, axis=0, truncate=4.0)
        np.testing.assert_allclose(y.values[4 * s : -4 * s], ref[4 * s : -4 * s], atol=1e-12)


def test_savgol_is_a_local_polynomial_fit_in_time():
    t = irregular(150, seed=6)
    x = _signal(t, seed=6)
    c = make("savgol", {"window": 0.2, "polyorder": 2}, names=NAMES)
    y = c.clean(Animation(t, x, NAMES)).values
    for n in (0, 40, 77, 149):
        near = np.abs(t - t[n]) <= 0.1
        coef = np.polyfit(t[near] - t[n], x[near], 2)
        np.testing.assert_allclose(y[n], coef[-1], atol=1e-9)
    # A polynomial of the filter's degree passes through unchanged, at any timing.
    poly = (0.2 + 0.5 * t - 0.3 * t**2)[:, None] * np.ones(3)
    np.testing.assert_allclose(c.clean(Animation(t, poly, NAMES)).values, poly, atol=1e-9)


def test_savgol_never_leaves_the_range_its_input_spans():
    # a blink's edges: the local polynomial overshoots under 0 and past 1 there (a negative
    # weight bends the face the other way); the output stays within its input's range
    t = np.arange(120) / 60.0
    x = np.zeros((120, 3))
    x[50:56] = 1.0  # a crisp blink, 0.1 s shut
    for window in (0.15, 0.3):
        fit = make("savgol", {"window": window}, names=NAMES).clean(Animation(t, x, NAMES))
        poly = savgol_filter(x, int(round(window * 60)) | 1, 2, axis=0)  # unclipped, for scale
        assert poly.min() < -0.02  # the polynomial itself overshoots here
        assert fit.values.min() >= 0.0 and fit.values.max() <= 1.0


def test_savgol_window_frames_is_scipy_on_a_regular_grid():
    t = np.arange(200) / 60.0
    x = _signal(t, seed=7)
    c = make("savgol", {"window_frames": 9, "polyorder": 3}, names=NAMES)
    y = c.clean(Animation(t, x, NAMES)).values
    np.testing.assert_allclose(y[4:-4], savgol_filter(x, 9, 3, axis=0)[4:-4], atol=1e-10)


@pytest.mark.parametrize(
    "method, params",
    [
        ("ema", {"tau": -1.0}),
        ("ema", {"tau": 0.1, "gamma": 0.5}),
        ("ema", {"gamma": 1.5}),
        ("ema", {"tau": [0.1, 0.2]}),
        ("ema", {"tau": "fast"}),
        ("one-euro", {"min_cutoff": 0.0}),
        ("one-euro", {"beta": True}),
        ("kalman", {"r": float("nan")}),
        ("gaussian", {"sigma": 0.1, "sigma_frames": 2}),
        ("savgol", {"window_frames": 8}),
        ("savgol", {"polyorder": 1.5}),
        ("kalman", {"bogus": 1.0}),
    ],
)
def test_bad_parameters_are_one_line_errors(method, params):
    with pytest.raises(FacecleanError) as e:
        make(method, params, names=NAMES)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("near", [False, True], ids=["vectorised", "near-duplicates"])
@pytest.mark.parametrize("seed", range(3))
def test_time_rules_over_sequences_equal_stepping_frame_by_frame(seed, near):
    """base.time_rules (the batched decision the LSTM's clean and the trainer use) gives
    what stepping decides frame by frame: duplicates, near-duplicates within MIN_DT,
    backwards times, pauses over max_gap, missing frames and non-finite times."""
    from faceclean.filters.base import MIN_DT, frame_rules, time_rules

    rng = np.random.default_rng(seed)
    S, T, max_gap = 3, 200, 0.5
    steps = [1 / 60, 0.0, -0.01, 0.7] + ([MIN_DT / 2, 2 * MIN_DT] if near else [])
    steps = rng.choice(steps, (S, T))
    t = np.cumsum(steps, axis=1) + 10.0
    t[rng.random((S, T)) < 0.03] = np.nan
    missing = rng.random((S, T)) < 0.1
    start, advance, dt = time_rules(t, missing, max_gap)
    prev = np.full(S, np.nan)
    for n in range(T):
        gone = missing[:, n] | ~np.isfinite(t[:, n])
        want_dt = t[:, n] - prev
        s, a = frame_rules(gone, want_dt, max_gap)
        np.testing.assert_array_equal(start[:, n], s)
        np.testing.assert_array_equal(advance[:, n], a)
        np.testing.assert_array_equal(dt[:, n], np.where(a, want_dt, np.nan))
        prev = np.where(s | a, t[:, n], prev)
    assert advance.any() and start[:, 1:].any() and (~(start | advance)).any()


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_ema_with_a_vanishing_time_constant_follows_the_input_without_a_warning():
    c = make("ema", {"tau": 1e-320}, names=["jawOpen"])
    t = np.arange(5) / 60.0
    x = np.linspace(0.1, 0.9, 5)[:, None]
    np.testing.assert_array_equal(steps(c, t, x), x)
