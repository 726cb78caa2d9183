"""The recurrent cleaner: closed loop, output residual, dt-normalised features, checkpoints."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from faceclean.errors import FacecleanError  # noqa: E402
from faceclean.neural import checkpoint  # noqa: E402
from faceclean.neural.model import LSTMCleaner  # noqa: E402

NAMES = ["a", "b", "c"]


def _model(K: int = 1, seed: int = 0, **kw) -> LSTMCleaner:
    torch.manual_seed(seed)
    m = LSTMCleaner(NAMES, K=K, hidden=16, layers=2, **kw)
    with torch.no_grad():  # non-trivial scales so that checkpoints carry them
        m.feat_mean.uniform_(-0.1, 0.1)
        m.feat_std.uniform_(0.5, 2.0)
        m.out_scale.uniform_(0.5, 2.0)
        m.head.weight.normal_(0.0, 0.3)  # the head starts at zero: make it do something
        m.head.bias.normal_(0.0, 0.3)
    return m.eval()


def _curve(fps: float, seconds: float = 1.0, B: int = 2):
    t = np.arange(0.0, seconds, 1.0 / fps)
    x = 0.5 + 0.3 * np.sin(2 * np.pi * np.outer(np.arange(1, B * 3 + 1), t) / 1.3).T
    x = x.reshape(len(t), B, 3).transpose(1, 0, 2)
    return torch.tensor(x, dtype=torch.float32), torch.tensor(np.tile(t, (B, 1)))


@pytest.mark.parametrize("output", ["additive", "gated"])  # gated: gain 1, correction 0
@pytest.mark.parametrize("K", [1, 2])
def test_zero_network_follows_the_input(K, output):
    assert not LSTMCleaner(NAMES, K=K, output=output).head.weight.any()  # a new model starts there
    m = _model(K, output=output)
    x, t = _curve(60.0)
    with torch.no_grad():
        assert not torch.allclose(m(x, t.float()), x, atol=1e-3)  # the head matters
    with torch.no_grad():
        m.head.weight.zero_()
        m.head.bias.zero_()
    x, t = _curve(60.0)
    y = m(x, t.float())
    assert torch.allclose(y, x, atol=1e-5)


def test_output_is_clamped_to_the_value_range():
    m = _model()
    with torch.no_grad():
        m.head.bias.fill_(1e4)  # far above the input's slopes
    x, t = _curve(60.0)
    with torch.no_grad():
        y = m(x, t.float())
    assert float(y.max()) <= 1.0 and float(y.min()) >= 0.0
    assert float(y[:, -1].min()) == 1.0


def test_closed_loop_consumes_its_own_outputs():
    m = _model()
    x, t = _curve(60.0, B=1)
    state = m.init_state(1, x[:, 0])
    dt = torch.full((1,), 1 / 60)
    for n in range(1, 10):
        state, _ = m.step(state, x[:, n], dt)
    changed = state._replace(y=state.y + 0.1)  # a different past output x̂[n] ...
    f1, _, _ = m.features(state, x[:, 10], dt)
    f2, _, _ = m.features(changed, x[:, 10], dt)
    assert not torch.allclose(f1, f2)  # ... changes the next input features
    _, y1 = m.step(state, x[:, 10], dt)
    _, y2 = m.step(changed, x[:, 10], dt)
    assert not torch.allclose(y1, y2)


def test_closed_loop_forward_equals_repeated_steps():
    m = _model(K=2)
    x, t = _curve(60.0)
    t = t.float()
    y, d, stepped = m(x, t, return_derivatives=True)
    state = m.init_state(2, x[:, 0])
    for n in range(1, x.shape[1]):
        state, yn = m.step(state, x[:, n], t[:, n] - t[:, n - 1])
        assert torch.allclose(yn, y[:, n], atol=1e-6)
        assert torch.allclose(state.d, d[:, n - 1], atol=1e-5)
    assert bool(stepped.all())


@pytest.mark.parametrize("K", [1, 2])
def test_features_are_dt_normalised(K):
    """A ramp sampled at 30 and at 60 fps gives the same corrective derivatives (units/s)."""
    m = _model(K)
    slope = torch.tensor([[0.4, -0.2, 0.1]])  # 1/s
    feats = []
    for fps in (30.0, 60.0):
        dt = torch.full((1,), 1.0 / fps)
        x0 = torch.full((1, 3), 0.5)
        state = m.init_state(1, x0)
        # on the ramp already: x̂[n] = x_i[n], x̂^(1)[n] = slope
        state = state._replace(z=slope.repeat(1, K - 1), xi=x0.repeat(1, K - 1))
        _, xc, xin = m.features(state, x0 + slope * dt, dt)
        feats.append(xc)
    assert torch.allclose(feats[0], feats[1], atol=1e-4)
    assert torch.allclose(feats[0][:, :3], slope, atol=1e-5)
    assert torch.allclose(feats[0][:, 3:], torch.zeros(1, 3 * (K - 1)), atol=1e-4)


def test_missing_frames_hold_the_output():
    m = _model()
    x, t = _curve(60.0)
    x[0, 5] = float("nan")
    y, _, stepped = m(x, t.float(), return_derivatives=True)
    assert torch.equal(y[0, 5], y[0, 4])
    assert not bool(stepped[0, 4]) and bool(stepped[1, 4])
    assert torch.isfinite(y).all()


@pytest.mark.parametrize("output", ["additive", "gated", "rate"])
def test_checkpoint_round_trip(tmp_path, output):
    m = _model(K=2, output=output)
    path = tmp_path / "m.npz"
    checkpoint.save(m, path, extra={"epochs": 3})
    back = checkpoint.load(path)
    x, t = _curve(60.0)
    with torch.no_grad():
        assert torch.equal(m(x, t.float()), back(x, t.float()))
    config, data = checkpoint.read(path)
    assert config["format"] == "faceclean-lstm/1" and config["epochs"] == 3
    assert config["output"] == output and back.output == output
    rows = 6 if output == "additive" else 12  # gated, rate: gain logits a, then corrections b
    assert data["lstm.1.w_hh"].shape == (64, 16) and data["head.w"].shape == (rows, 16)
    assert data["feat_mean"].shape == (15,) and data["out_scale"].shape == (6,)
    assert all(v.dtype == np.float32 for v in data.values())


def test_checkpoint_keeps_optimizer_state(tmp_path):
    m = _model().train()
    opt = torch.optim.Adam(m.parameters(), lr=1e-3)
    x, t = _curve(60.0)
    m(x, t.float()).square().mean().backward()
    opt.step()
    checkpoint.save(m, tmp_path / "m.npz", optimizer=opt)
    back, _, optim = checkpoint.load_training(tmp_path / "m.npz")
    opt2 = torch.optim.Adam(back.parameters(), lr=1e-3)
    checkpoint.load_optimizer(back, opt2, optim)
    p, p2 = next(iter(m.parameters())), next(iter(back.parameters()))
    assert torch.equal(opt.state[p]["exp_avg_sq"], opt2.state[p2]["exp_avg_sq"])


def test_foreign_or_malformed_checkpoints_are_refused(tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(FacecleanError):
        checkpoint.load(junk)
    np.savez(tmp_path / "other.npz", config=np.array(json.dumps({"format": "x"})))
    with pytest.raises(FacecleanError, match="not a"):
        checkpoint.load(tmp_path / "other.npz")
    m = _model()
    checkpoint.save(m, tmp_path / "m.npz")
    config, data = checkpoint.read(tmp_path / "m.npz")
    data["head.w"] = data["head.w"][:, :3]
    np.savez(tmp_path / "bad.npz", config=np.array(json.dumps(config)), **data)
    with pytest.raises(FacecleanError, match="shape"):
        checkpoint.load(tmp_path / "bad.npz")
    with pytest.raises(FacecleanError, match="no such"):
        checkpoint.load(tmp_path / "absent.npz")
