"""ONNX export (faceclean export) and the ONNX Runtime backend.

The exported graph is one step with all state explicit; run by onnxruntime it must give
the numpy runtime's numbers (tolerance 1e-5; measured about 1e-7).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean import Animation, Cleaner, FacecleanError
from faceclean.channels import ARKIT52
from faceclean.cli import main
from faceclean.learned.checkpoint import LSTMWeights
from faceclean.learned.lstm import Learned

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")
TOL = 1e-5


@pytest.fixture(scope="module", params=["additive", "gated", "rate"])  # the output heads
def files(tmp_path_factory, request):
    d = tmp_path_factory.mktemp("export")
    w = LSTMWeights.random(ARKIT52, seed=4, layers=3, output=request.param)  # 2 residual layers
    w = LSTMWeights.from_arrays({**w.to_arrays(), "out_scale": np.full(52, 3.0, np.float32)})
    w.save(d / "m.npz")
    assert main(["export", str(d / "m.npz"), "-o", str(d / "m.onnx")]) == 0
    return w, d / "m.npz", d / "m.onnx"


def test_graph_has_explicit_state_and_metadata(files):
    w, _, path = files
    model = onnx.load(path)
    onnx.checker.check_model(model)
    inputs = [i.name for i in model.graph.input]
    outputs = [o.name for o in model.graph.output]
    state = ["y", "d", "h0", "c0", "h1", "c1", "h2", "c2"]
    assert inputs == ["x_new", "dt", *state]
    assert outputs == [f"{s}_next" for s in state]
    meta = {p.key: p.value for p in model.metadata_props}
    assert json.loads(meta["channels"]) == list(ARKIT52)
    assert json.loads(meta["config"])["layers"] == 3
    assert json.loads(meta["config"])["output"] == w.output
    np.testing.assert_allclose(json.loads(meta["feat_std"]), w.feat_std, rtol=1e-6)
    assert json.loads(meta["state"]) == state
    assert meta["faceclean.format"] == "faceclean-lstm-step/1"


def test_one_raw_step_in_onnxruntime_equals_numpy(files):
    w, _, path = files
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(0)
    S = 3
    x0, x1 = rng.uniform(0, 1, (2, S, 52))
    c = Learned(weights=w, kernel="numpy")
    c.step(x0, np.zeros(S))
    want = c.step(x1, np.array([0.01, 0.02, 0.05]))
    feeds = {"x_new": x1.astype(np.float32), "dt": np.array([[0.01], [0.02], [0.05]], np.float32)}
    feeds |= {"y": x0.astype(np.float32), "d": np.zeros((S, 52), np.float32)}
    feeds |= {f"{k}{i}": np.zeros((S, 128), np.float32) for i in range(3) for k in "hc"}
    y_next, d_next, *_ = sess.run(None, feeds)
    np.testing.assert_allclose(y_next, want, atol=TOL)
    assert not np.allclose(y_next, x1, atol=1e-3)  # the network changed something
    np.testing.assert_allclose(d_next, c._ws.d.T, rtol=1e-4, atol=1e-3)  # 1/s, larger


def test_onnx_backend_cleans_like_numpy(files):
    _, npz, path = files
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.008, 0.04, 160))
    x = np.clip(0.4 + np.cumsum(rng.normal(0, 0.03, (160, 52)), axis=0), 0, 1)
    x[50] = np.nan  # a missing frame
    x[80, :4] = np.nan  # NaN channels
    t[120:] += 1.0  # a pause: restart
    anim = Animation.from_arkit(t, x)
    want = Cleaner.load(npz).clean(anim).values
    for c in (Cleaner.load(path), Cleaner.load(npz, backend="onnx")):
        assert "onnx" in c.source
        got = c.clean(anim).values
        assert np.isnan(got[50]).all()
        np.testing.assert_allclose(np.delete(got, 50, 0), np.delete(want, 50, 0), atol=TOL)
    many = Cleaner.load(path, streams=2)
    y = many.step(np.stack([x[0], x[1]]), t[:2])
    np.testing.assert_allclose(y, np.stack([x[0], x[1]]), atol=1e-7)  # first frames pass


def test_export_refuses_bad_input(tmp_path, files, capsys):
    _, npz, _ = files
    bad = tmp_path / "bad.npz"
    bad.write_text("not a model")
    out = tmp_path / "out.onnx"
    assert main(["export", str(bad), "-o", str(out)]) == 2
    assert main(["export", str(tmp_path / "none.npz"), "-o", str(out)]) == 2
    assert main(["export", str(npz), "-o", str(tmp_path / "no" / "dir.onnx")]) == 2
    assert main(["export", str(npz), "-o", str(tmp_path / "model.txt")]) == 2  # was written
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 4 and all(e.startswith("faceclean: ") for e in err)
    assert "an ONNX graph is a .onnx file" in err[-1]
    assert not out.exists() and not (tmp_path / "model.txt").exists()
    from faceclean.learned.onnx import OnnxLearned

    with pytest.raises(FacecleanError, match="not a loadable ONNX model"):
        OnnxLearned(b"garbage")
    foreign = onnx.helper.make_model(
        onnx.helper.make_graph(
            [onnx.helper.make_node("Identity", ["a"], ["b"])],
            "g",
            [onnx.helper.make_tensor_value_info("a", onnx.TensorProto.FLOAT, [1])],
            [onnx.helper.make_tensor_value_info("b", onnx.TensorProto.FLOAT, [1])],
        ),
        opset_imports=[onnx.helper.make_opsetid("", 17)],
    )
    foreign.ir_version = 8
    with pytest.raises(FacecleanError, match="not a faceclean step graph"):
        OnnxLearned(foreign.SerializeToString())


def test_export_check_flag(files, tmp_path, capsys):
    _, npz, _ = files
    assert main(["export", str(npz), "-o", str(tmp_path / "c.onnx"), "--check"]) == 0
    assert "max |diff|" in capsys.readouterr().out
