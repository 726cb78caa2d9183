"""``faceclean clean --model FILE``: a user's own model, as .npz or exported .onnx."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import REPO, shared

from faceclean import io
from faceclean.channels import ARKIT52
from faceclean.cli import main
from faceclean.learned.adaptive import FORMAT, N_FEATURES, Adaptive, AdaptiveWeights

REPO_MODELS = REPO / "benchmarks" / "models"


def _take():
    return shared("arkit_takes", "jmtechart", "MySlate_3_iPhone.csv")


def _weights(seed: int = 0, H: int = 6, E: int = 3) -> AdaptiveWeights:
    """A small adaptive model with random weights, written without torch."""
    rng = np.random.default_rng(seed)
    M, F = 52, N_FEATURES + E
    arrays = {
        "emb": rng.normal(0, 0.3, (M, E)), "gru.w_ih": rng.normal(0, 0.3, (3 * H, F)),
        "gru.w_hh": rng.normal(0, 0.3, (3 * H, H)), "gru.b_ih": rng.normal(0, 0.1, 3 * H),
        "gru.b_hh": rng.normal(0, 0.1, 3 * H), "head.w": rng.normal(0, 0.5, (2, H)),
        "head.b": np.array([0.0, -3.0]), "boost": rng.normal(0, 0.3, M),
        "min_cutoff": np.full(M, 1.5), "beta": np.full(M, 3.0), "d_cutoff": np.ones(M),
    }  # fmt: skip
    config = {"format": FORMAT, "channels": list(ARKIT52), "hidden": H, "embed": E}
    return AdaptiveWeights.from_arrays(config, arrays)


def test_clean_with_an_npz_model(tmp_path, capsys):
    w = _weights()
    model = tmp_path / "mine.npz"
    w.save(model)
    out = tmp_path / "out.csv"
    assert main(["clean", str(_take()), "-o", str(out), "--model", str(model)]) == 0
    assert "adaptive (numpy)" in capsys.readouterr().out
    got, take = io.load(out), io.load(_take())
    want = Adaptive(weights=AdaptiveWeights.load(model), names=take.names).clean(take)
    assert np.allclose(got.values, want.values, atol=1e-6, equal_nan=True)
    assert not np.allclose(got.values, take.values, atol=1e-4, equal_nan=True)


def test_clean_with_an_onnx_model(tmp_path):
    pytest.importorskip("onnxruntime")
    lstm = REPO_MODELS / "lstm-alexdjulin.npz"
    graph = tmp_path / "lstm.onnx"
    assert main(["export", str(lstm), "-o", str(graph)]) == 0
    a, b = tmp_path / "onnx.csv", tmp_path / "npz.csv"
    assert main(["clean", str(_take()), "-o", str(a), "--model", str(graph)]) == 0
    assert main(["clean", str(_take()), "-o", str(b), "--model", str(lstm)]) == 0
    # the same model on two backends: the CSV's printed digits agree
    assert np.allclose(io.load(a).values, io.load(b).values, atol=2e-4, equal_nan=True)


@pytest.mark.parametrize(
    ("name", "extra", "says"),
    [
        ("none.npz", [], "no such model file"),
        ("model.txt", [], "a model is a .npz or an .onnx file"),
        ("mine.npz", ["--method", "kalman"], "--model is the cleaner"),
    ],
)
def test_bad_model_arguments_are_one_line_errors(tmp_path, capsys, name, extra, says):
    _weights().save(tmp_path / "mine.npz")
    (tmp_path / "model.txt").write_text("not a model")
    out = tmp_path / "out.csv"
    argv = ["clean", str(_take()), "-o", str(out), "--model", str(tmp_path / name), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
