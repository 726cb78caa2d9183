"""The paper's FC and GBT baselines: numpy runtime against torch / scikit-learn, the blend,
the derivative features, and a tiny end-to-end training run."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.learned.derivative_net import (
    BoostedTrees,
    DerivativeFeatures,
    FullyConnected,
    blend,
)

torch = pytest.importorskip("torch")
pytest.importorskip("sklearn")
from faceclean.neural import baselines  # noqa: E402

M, K = 52, 4


def _features(n: int, seed: int) -> np.ndarray:
    """(n, M, 1 + 2K) features with the spread of real ones (orders grow with fps^k)."""
    rng = np.random.default_rng(seed)
    scale = np.array([0.3, 3, 300, 3e4, 3e6, 3, 300, 3e4, 3e6])
    return rng.normal(0, 1, (n, M, 1 + 2 * K)) * scale


def test_fc_numpy_runtime_equals_torch(tmp_path):
    torch.manual_seed(0)
    net = baselines.FCNet(M, hidden=(32, 16))
    rng = np.random.default_rng(1)
    f = (1 + 2 * K) * M
    net.feat_mean.copy_(torch.from_numpy(rng.normal(0, 1, f)))
    net.feat_std.copy_(torch.from_numpy(np.abs(_features(1, 2)).reshape(-1) + 0.5))
    net.out_mean.copy_(torch.from_numpy(rng.normal(0, 1, K * M)))
    net.out_std.copy_(torch.from_numpy(rng.uniform(0.5, 100, K * M)))
    net.eval()
    path = tmp_path / "fc.npz"
    baselines.save_fc(net, path, {"val_sources": ["x"]})
    feats = _features(64, 3)
    with torch.no_grad():
        want = net(torch.from_numpy(feats).float()).double().numpy()
    fc = FullyConnected(model=path)
    got = fc.predict(feats)
    assert got.shape == (64, M, K)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-4 * np.abs(want).max())
    assert fc.alpha == 0.9 and fc.config["val_sources"] == ["x"]


@pytest.fixture(scope="module")
def gbt_model(tmp_path_factory):
    """A small GBT fitted on random features, its regressors, σ and the file."""
    feats = _features(300, 4)
    rng = np.random.default_rng(5)
    targets = np.stack(
        [feats[..., 1] * 0.5 + np.sin(feats[..., 0] * 5), *(rng.normal(0, 9, (3, 300, M)))], -1
    )
    regs, sigma = baselines.fit_gbt(feats, targets, iterations=(6, 3, 3, 3), depth=4)
    path = tmp_path_factory.mktemp("gbt") / "gbt.npz"
    baselines.export_gbt(regs, sigma, path, {"val_sources": []})
    return regs, sigma, path


def test_gbt_numpy_runtime_equals_sklearn(gbt_model):
    regs, sigma, path = gbt_model
    gbt = BoostedTrees(model=path)
    feats = _features(50, 6)
    got = gbt.predict(feats)  # (50, M, K)
    groups = np.broadcast_to(baselines.group_index(ARKIT52)[None, :, None], (50, M, 1))
    x = np.concatenate([feats, groups], -1).reshape(50 * M, -1)
    want = np.stack([r.predict(x) * s for r, s in zip(regs, sigma, strict=True)], -1)
    np.testing.assert_allclose(got.reshape(50 * M, K), want, rtol=1e-12, atol=1e-12)
    assert np.ptp(want[:, 0]) > 0  # the trees do split
    assert gbt.alpha == 0.97


def test_gbt_compiled_step_gives_numpys_bits(gbt_model):
    """learned/jit.trees (a step's trees with numba) against the numpy descent, on
    features with NaN (it goes left) and the shipped model's trees, grouped by order."""
    pytest.importorskip("numba")
    feats = _features(7, 9)
    feats[2, 5, 3] = np.nan
    for gbt in (BoostedTrees(model=gbt_model[2]), BoostedTrees()):
        f = np.ascontiguousarray(feats.transpose(0, 2, 1))  # (S, 1 + 2K, M), a step's state
        compiled = gbt._predict_fm(f)
        assert gbt._jit  # the kernel ran
        numpy = gbt.predict(feats).transpose(0, 2, 1)
        np.testing.assert_array_equal(compiled, numpy)
        assert np.ptp(numpy) > 0


def test_gbt_batched_clean_equals_stepping(gbt_model):
    t = np.cumsum(np.random.default_rng(7).uniform(0.5, 1.5, 120)) / 60.0
    x = np.clip(0.5 + 0.2 * np.sin(t[:, None] * np.arange(1, M + 1) / 7), 0, 1)
    x[30] = np.nan
    x[50, 4] = np.nan  # a lost channel takes the last output (stepping's, not a guess)
    gbt = BoostedTrees(model=gbt_model[2])
    batch = gbt.clean(Animation(t, x, ARKIT52)).values
    gbt.reset()
    stepped = np.array([gbt.step(x[i], t[i]) for i in range(len(t))])
    stepped[30] = np.nan
    np.testing.assert_array_equal(batch, stepped)
    assert not np.allclose(batch[1:], x[1:], equal_nan=True)  # it did something


def test_blend_alpha_zero_follows_prediction_and_one_holds():
    rng = np.random.default_rng(8)
    r = rng.normal(size=(3, K, M))  # X_r^(0..K-1) of 3 streams
    d_hat = rng.normal(size=(3, K, M))
    x = rng.normal(size=(3, M))
    out = blend(r, d_hat, x, 0.02, alpha=0.0)
    np.testing.assert_array_equal(out[:, 0], x)  # X_r^(0) = X̂^(0) = X_i
    for k in range(1, K):
        np.testing.assert_array_equal(out[:, k], d_hat[:, k - 1])
    held = blend(r, np.zeros_like(r), x, 0.02, alpha=1.0)
    np.testing.assert_array_equal(held, r)
    mid = blend(r, d_hat, x, 0.02, alpha=0.9)  # the complementary mix, by hand
    np.testing.assert_allclose(mid[:, 0], 0.9 * (r[:, 0] + 0.02 * d_hat[:, 0]) + 0.1 * x)
    np.testing.assert_allclose(mid[:, 2], 0.9 * (r[:, 2] + 0.02 * d_hat[:, 2]) + 0.1 * d_hat[:, 1])


def test_features_are_backward_derivatives_in_seconds():
    fps, a = 60.0, 0.4
    t = np.arange(20) / fps
    x = np.tile((a * t**2)[:, None], (1, M))  # x' = 2at, x'' = 2a
    feats, age = DerivativeFeatures(K=K).features(Animation(t, x, ARKIT52))
    assert feats.shape == (19, M, 1 + 2 * K)
    dt = 1 / fps
    n = 10  # feats[i] is the step onto frame i + 1
    np.testing.assert_allclose(feats[n - 1, 0, 0], x[n, 0])
    np.testing.assert_allclose(feats[n - 1, 0, 1], a * (2 * t[n] - dt))  # (x[n]-x[n-1])/dt
    np.testing.assert_allclose(feats[n - 1, 0, 2], 2 * a, rtol=1e-6)
    np.testing.assert_allclose(feats[n - 1, 0, 3:5], 0, atol=1e-4)
    np.testing.assert_allclose(feats[n - 1, 0, 5], a * (2 * t[n - 1] - dt))  # at n-1
    np.testing.assert_array_equal(age[:, 0], np.arange(19))
    # The same curve at 120 fps gives the same derivatives: dt-normalised.
    t2 = np.arange(40) / 120.0
    f2, _ = DerivativeFeatures(K=K).features(
        Animation(t2, np.tile(a * t2[:, None] ** 2, M), ARKIT52)
    )
    np.testing.assert_allclose(f2[-1, 0, 2], 2 * a, rtol=1e-5)


def test_tiny_training_run_writes_a_working_model(tmp_path):
    from faceclean import io
    from faceclean.cli import main
    from faceclean.datasets import performer

    for source in ("one", "two"):
        (tmp_path / source).mkdir()
        anim = performer.perform(4.0, seed=len(source), fps=60.0)
        io.save(anim, tmp_path / source / "take.csv")
    out = tmp_path / "gbt.npz"
    argv = ["train", "--arch", "gbt", "--data", str(tmp_path), "--val-sources", "two"]
    assert main([*argv, "--out", str(out)]) == 0
    gbt = BoostedTrees(model=out)
    assert gbt.config["val_sources"] == ["two"] and gbt.config["train_sources"] == ["one"]
    clip = io.load(tmp_path / "two" / "take.csv")
    y = gbt.clean(clip).values
    assert y.shape == clip.values.shape and np.isfinite(y).all()
    assert main([*argv, "--out", str(tmp_path / "x.txt")]) == 2  # bad --out: exit 2


@pytest.mark.parametrize("method", ["fc", "gbt"])
def test_the_bench_reference_for_a_baseline_computes_the_same_function(method):
    # issue 19: each shipped learned cleaner is timed against eager torch on its own model
    pytest.importorskip("torch")
    from faceclean.filters import make
    from faceclean.neural.reference import DerivativeReference

    ours = make(method)
    ref = DerivativeReference(make(method))
    rng = np.random.default_rng(7)
    x = np.clip(0.4 + np.cumsum(rng.normal(0, 0.02, (150, 2, 52)), axis=0), 0, 1)
    dt = rng.uniform(0.5, 1.5, (150, 2)) / 60.0
    t = np.cumsum(dt, axis=0)
    ref.start(x[0])
    ours.step(x[0], t[0])
    for n in range(1, 150):
        want = ours.step(x[n], t[n])
        tol = 1e-9 if method == "gbt" else 2e-5  # FC: float32 layers on both sides
        np.testing.assert_allclose(ref.step(x[n], t[n] - t[n - 1]), want, atol=tol)
