"""Metrics on analytic signals whose answers are known."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import irregular

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.evaluation import metrics


def _blinks(t: np.ndarray, centres: list[float], width: float = 0.05) -> np.ndarray:
    return sum(np.exp(-0.5 * ((t - c) / width) ** 2) for c in centres)


def test_mse_known_value_and_nan_ignored():
    truth = np.zeros((4, 2))
    pred = np.full((4, 2), 0.5)
    pred[1] = np.nan
    assert metrics.mse(pred, truth) == pytest.approx(0.25)


@pytest.mark.parametrize("delay_ms", [0.0, 33.0, 80.0, -20.0])
def test_lag_of_shifted_sine(delay_ms):
    t = irregular(600, 60.0, spread=(0.6, 1.4))  # ~10 s, irregular
    f = np.array([0.7, 1.3, 2.1])  # Hz
    truth = 0.5 + 0.4 * np.sin(2 * np.pi * f * t[:, None])
    pred = 0.5 + 0.4 * np.sin(2 * np.pi * f * (t[:, None] - delay_ms / 1000))
    assert metrics.lag_ms(t, pred, truth) == pytest.approx(delay_ms, abs=0.6)


def test_lag_nan_on_motionless_truth():
    t = np.arange(100) / 60
    assert np.isnan(metrics.lag_ms(t, np.ones((100, 2)), np.ones((100, 2))))


def test_blink_scaled_by_06_gives_06():
    t = np.arange(600) / 60.0
    truth = np.zeros((600, 3))
    truth[:, 0] = 0.9 * _blinks(t, [1.0, 3.5, 7.0])  # eyeBlinkLeft
    truth[:, 1] = 0.8 * _blinks(t, [2.0, 6.0])  # eyeBlinkRight
    pred = truth * 0.6
    names = ["EyeBlinkLeft", "eyeBlink_R", "jawOpen"]
    assert metrics.blink_closure(t, pred, truth, names) == pytest.approx(0.6)
    # A 2-frame late output still reaches its peak within the window.
    late = np.roll(truth, 2, axis=0)
    assert metrics.blink_closure(t, late, truth, names) == pytest.approx(1.0)


def test_blink_nan_without_blinks():
    t = np.arange(100) / 60
    small = 0.1 * _blinks(t, [0.8])[:, None]  # prominence 0.1 < 0.3: no blink
    assert np.isnan(metrics.blink_closure(t, small, small, ["eyeBlinkLeft"]))


def test_white_noise_raises_jitter_on_irregular_times():
    t = irregular(400, 60.0, seed=1, spread=(0.6, 1.4))
    truth = 0.5 + 0.3 * np.sin(2 * np.pi * 1.0 * t)[:, None] * np.ones((1, 4))
    assert metrics.jitter_ratio(t, truth, truth) == pytest.approx(1.0)
    noisy = truth + np.random.default_rng(2).normal(0, 0.02, truth.shape)
    assert metrics.jitter_ratio(t, noisy, truth) > 50.0
    assert metrics.jitter_ratio(t, 0.5 * truth, truth) == pytest.approx(0.25)


def test_second_derivative_exact_on_parabola_irregular():
    t = irregular(50, 30.0, seed=3, spread=(0.6, 1.4))
    x = (3.0 * t**2 + t)[:, None]
    d2 = metrics._second_derivative(t, x)
    np.testing.assert_allclose(d2, 6.0, rtol=1e-6)


def test_summary_matches_by_name_and_ignores_missing_frames():
    t = np.arange(600) / 60.0
    vals = np.zeros((600, 52))
    vals[:, 0] = 0.9 * _blinks(t, [2.0, 5.0])
    vals[:, 17] = 0.3 + 0.2 * np.sin(2 * np.pi * 0.8 * t)
    truth = Animation(t, vals, ARKIT52)
    # Prediction: other spellings, other order, a missing frame, 50 ms late.
    late = np.zeros_like(vals)
    late[:, 0] = 0.9 * _blinks(t - 0.05, [2.0, 5.0])
    late[:, 17] = 0.3 + 0.2 * np.sin(2 * np.pi * 0.8 * (t - 0.05))
    order = np.arange(52)[::-1]
    pred = Animation(t, late[:, order], [ARKIT52[i].upper() for i in order])
    pred.values[100] = np.nan
    s = metrics.summary(pred, truth)
    assert set(s) == {"mse", "jitter_ratio", "lag_ms", "blink_closure"}
    assert s["lag_ms"] == pytest.approx(50.0, abs=1.0)
    assert s["blink_closure"] == pytest.approx(1.0, abs=0.02)
    assert np.isfinite(s["mse"]) and s["mse"] > 0
    same = metrics.summary(truth, truth)
    assert same["mse"] == 0.0 and same["jitter_ratio"] == 1.0


def test_summary_refuses_mismatched_frames():
    a = Animation(np.arange(5.0), np.zeros((5, 1)), ["jawOpen"])
    b = Animation(np.arange(4.0), np.zeros((4, 1)), ["jawOpen"])
    with pytest.raises(FacecleanError):
        metrics.summary(a, b)
