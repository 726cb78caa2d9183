"""Losses and training of the recurrent cleaner, on small synthetic arrays and real takes."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from faceclean.channels import ARKIT52, INDEX  # noqa: E402
from faceclean.face.mesh import FaceMesh  # noqa: E402
from faceclean.face.vertex_pairs import LossFace  # noqa: E402
from faceclean.neural import checkpoint  # noqa: E402
from faceclean.neural.losses import Loss, Weights  # noqa: E402
from faceclean.neural.model import LSTMCleaner  # noqa: E402
from faceclean.neural.train import Config, feature_stats, last_path, train  # noqa: E402
from faceclean.settings import takes_dir  # noqa: E402


@pytest.fixture(autouse=True)
def _one_thread():
    """Tiny models: one thread is fastest, and the machine is shared."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _face() -> LossFace:
    """A toy face: pair 0 opens with jawOpen, pair 4 closes with eyeBlinkLeft."""
    neutral = np.zeros((12, 3))
    neutral[1::2, 1] = 0.01  # every pair (2i, 2i+1) starts 1 cm apart
    neutral[6, 0], neutral[7, 0] = -0.02, 0.02  # mouth corners, 4 cm
    deltas = np.zeros((52, 12, 3))
    deltas[INDEX["jawOpen"], 0, 1] = -0.03
    deltas[INDEX["eyeBlinkLeft"], 9, 1] = -0.01
    mesh = FaceMesh(neutral, np.zeros((0, 3), np.uint32), deltas)
    return LossFace(mesh, np.arange(12).reshape(6, 2), scale=0.04)


def _batch(B=4, T=60, fps=60.0, seed=0, M=52):
    rng = np.random.default_rng(seed)
    t = np.tile(np.arange(T) / fps, (B, 1))
    phase = rng.uniform(0, 6, (B, 1, M))
    truth = 0.5 + 0.3 * np.sin(2 * np.pi * 0.7 * t[..., None] + phase)
    noisy = truth + rng.normal(0, 0.02, truth.shape)
    f = lambda a: torch.tensor(a, dtype=torch.float32)  # noqa: E731
    return f(noisy), f(truth), f(t), torch.ones(B, T, dtype=torch.bool)


def test_loss_is_zero_for_the_truth_and_masks_missing_frames():
    noisy, truth, t, valid = _batch()
    loss = Loss(ARKIT52, _face(), Weights(dis=0.0))
    d = (truth[:, 1:] - truth[:, :-1]) / (t[:, 1:] - t[:, :-1]).unsqueeze(-1)
    stepped = torch.ones(d.shape[:2], dtype=torch.bool)
    total, parts = loss(truth, d, stepped, noisy, truth, t, valid)
    assert float(total) == pytest.approx(0.0, abs=1e-6)
    bad = truth.clone()
    bad[:, 30] += 0.5  # a wrong frame ...
    total, parts = loss(bad, d, stepped, noisy, truth, t, valid)
    assert parts["mse"] > 0 and parts["acc"] > 0
    valid[:, 30] = False  # ... that the tracker lost counts in no term
    total, parts = loss(bad, d, stepped, noisy, truth, t, valid)
    assert float(total) == pytest.approx(0.0, abs=1e-6)


def test_distance_term_follows_the_mesh():
    loss = Loss(ARKIT52, _face())
    x = torch.zeros(1, 2, 52)
    x[0, 1, INDEX["jawOpen"]] = 1.0
    x[0, 1, INDEX["eyeBlinkLeft"]] = 1.0
    D = loss.distances(x)[0]  # (2, 6) in mouth widths
    assert D[0, 0] == pytest.approx(0.25) and D[1, 0] == pytest.approx(1.0)  # 1 cm -> 4 cm
    assert D[0, 4] == pytest.approx(0.25) and D[1, 4] == pytest.approx(0.0, abs=1e-6)
    assert np.allclose(loss.distances(x).numpy(), _face().distances(x.numpy()), atol=1e-6)


def test_feature_scales_come_from_the_data():
    noisy, truth, t, _ = _batch(fps=30.0)
    m = LSTMCleaner(ARKIT52, hidden=8, layers=1)
    feature_stats(m, noisy.numpy(), truth.numpy(), t.numpy())
    M = 52
    assert np.allclose(m.feat_mean[:M].numpy(), truth.numpy().reshape(-1, M).mean(0), atol=1e-4)
    # noise 0.02 at 30 fps: corrective derivatives ~ 0.02 * 30 * sqrt(2) /s
    assert 0.5 < float(m.feat_std[2 * M :].mean()) < 1.5
    assert 0.3 < float(m.out_scale.mean()) < 1.2


def test_a_tiny_training_run_lowers_the_loss():
    torch.manual_seed(0)
    names = ["jawOpen", "eyeBlinkLeft", "mouthClose", "browInnerUp"]  # M = 4 of ARKit's
    noisy, truth, t, valid = _batch(B=8, T=40, M=len(names))
    m = LSTMCleaner(names, hidden=16, layers=2, dropout=0.0)
    feature_stats(m, noisy.numpy(), truth.numpy(), t.numpy())
    loss = Loss(names, _face())
    opt = torch.optim.Adam(m.parameters(), lr=1e-2)
    history = []
    for _ in range(25):
        y, d, s = m(noisy, t, return_derivatives=True)
        total, _ = loss(y, d, s, noisy, truth, t, valid)
        opt.zero_grad()
        total.backward()
        opt.step()
        history.append(float(total.detach()))
    assert history[-1] < 0.6 * history[0]  # noise 0.02: following the input costs ~4e-4


@pytest.mark.skipif(takes_dir() is None, reason="shared data arkit_takes/ absent")
def test_train_on_real_takes_writes_and_resumes(tmp_path):
    out = tmp_path / "m.npz"
    cfg = Config(
        out=str(out), val_sources=("jmtechart",), epochs=1, batch=4, hidden=8, layers=1,
        max_batches=2, seed=3,
    )  # fmt: skip
    events = []
    best = train(cfg, events.append)
    assert best["epoch"] == 0 and set(best["val"]) == {"60 fps", "webcam"}
    assert {"start", "batch", "epoch", "stop"} <= {e["event"] for e in events}
    config, _ = checkpoint.read(out)
    assert config["val_sources"] == ["jmtechart"] and "jmtechart" not in config["train_sources"]
    assert checkpoint.load(out).hidden == 8
    # resume: one more epoch from the saved optimizer state
    cfg.epochs, cfg.resume = 2, str(last_path(out))
    events.clear()
    train(cfg, events.append)
    assert [e["epoch"] for e in events if e["event"] == "epoch"] == [1]


def test_train_command_refuses_bad_arguments(tmp_path, capsys):
    from faceclean.cli import main

    assert main(["train", "--epochs", "1"]) == 2  # no --out
    assert main(["train", "--out", str(tmp_path / "m.pt")]) == 2
    err = capsys.readouterr().err
    assert err.count("faceclean: ") == 2 and ".npz" in err and "Traceback" not in err


@pytest.fixture
def tiny_takes(tmp_path):
    """Two sources of two 3 s synthetic takes each (train --data layout)."""
    from faceclean import io
    from faceclean.datasets.performer import perform

    for source, seeds in (("a", (1, 2)), ("b", (3, 4))):
        (tmp_path / source).mkdir()
        for s in seeds:
            io.save(perform(3.0, seed=s), tmp_path / source / f"t{s}.csv")
    return tmp_path


@pytest.mark.parametrize("words", ["default", "lstm", "copy"])
def test_train_report_takes_any_model_and_shipped_names(
    tiny_takes, tmp_path_factory, capsys, words
):
    # issue 19: "--report default" said "no such model file"; "--report mine.npz" refused
    # an adaptive model ("not a faceclean-lstm/1 model")
    import shutil

    from faceclean.cli import main
    from faceclean.settings import MODELS

    if words == "copy":  # a user's own adaptive model file
        words = str(tmp_path_factory.mktemp("models") / "mine.npz")
        shutil.copyfile(MODELS / "default.npz", words)
    argv = ["train", "--report", words, "--data", str(tiny_takes), "--val-sources", "b"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "on b (2 takes)" in out
    rows = [ln for ln in out.splitlines() if ln.startswith("| ") and "fps" in ln]
    assert len(rows) == 3 and all("nan" not in r for r in rows), out  # 30, 60, 120 fps
    ratios = [float(r.split("|")[4]) for r in rows]
    assert all(0.0 < v < 1.5 for v in ratios), rows


def test_train_report_refuses_what_is_no_model_in_one_line(tiny_takes, capsys):
    from faceclean.cli import main

    for words in ("nothere.npz", str(tiny_takes / "a" / "t1.csv")):
        assert main(["train", "--report", words, "--data", str(tiny_takes)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "model" in err[0] and "internal error" not in err[0], err
