"""The benchmark's learned rows compute what the runtime computes (issue 38, item 2).

No timing is asserted: the MediaPipe map's row is the cleaner ``clean --tracker mediapipe``
runs, its eager torch reference computes the same function (the shipped map, and one with
the parts the shipped map leaves out: a lift with its top, a hidden layer), the bench runs
without torch and says so, and FC's compiled step for many streams gives numpy's bits.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from helpers import NOT_INSTALLED

from faceclean.channels import ARKIT52
from faceclean.evaluation import bench


def _walk(n: int, s: int, m: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, s, m) frames in [0, 1] with blinks, (n, s) s at an uneven ~60 fps."""
    rng = np.random.default_rng(seed)
    x = np.clip(0.3 + np.cumsum(rng.normal(0, 0.03, (n, s, m)), axis=0), 0, 1)
    x[n // 3 : n // 3 + 6, :, :8] = 0.95  # a closure: the lift's rise
    t = np.cumsum(rng.uniform(0.5, 1.5, (n, s)) / 60.0, axis=0)
    return x, t


def test_the_map_row_is_the_cleaner_clean_tracker_mediapipe_runs(tmp_path):
    from faceclean import io
    from faceclean.animation import Animation
    from faceclean.cli import main
    from faceclean.learned.map_weights import MapWeights
    from faceclean.learned.tracker_map import TrackerMap
    from faceclean.settings import MODELS

    ours = bench.tracker_map()
    assert isinstance(ours, TrackerMap) and ours.names == ARKIT52
    shipped = MapWeights.load(MODELS / "mediapipe.npz")
    assert ours.weights.config == shipped.config
    for key, a in shipped.arrays.items():
        np.testing.assert_array_equal(ours.weights.arrays[key], a)
    x, t = _walk(240, 1, 52, 3)
    take = Animation.from_arkit(t[:, 0], x[:, 0])
    io.save(take, tmp_path / "take.csv")
    argv = ["clean", str(tmp_path / "take.csv"), "--tracker", "mediapipe"]
    assert main([*argv, "-o", str(tmp_path / "out.csv")]) == 0
    cleaned = io.load(tmp_path / "out.csv")
    np.testing.assert_allclose(cleaned.values, ours.clean(take).values, rtol=0, atol=1e-12)


def _richer_map():
    """The shipped map with a lift (its top kept), a hidden layer, the band widened by the
    noise and the rest smoothed after a warm-up: every branch of the step the shipped file
    does not take."""
    from faceclean.learned.map_weights import MapWeights
    from faceclean.learned.tracker_map import TrackerMap
    from faceclean.settings import MODELS

    w = MapWeights.load(MODELS / "mediapipe.npz")
    rng = np.random.default_rng(11)
    k, m, h = len(w.inputs), len(w.outputs), 6
    arrays = dict(w.arrays)
    own = [j for j, name in enumerate(w.outputs) if name in w.inputs][:8]
    arrays["lift_gain"] = np.zeros(m)
    arrays["lift_gain"][own] = 3.0
    arrays["lift_knee"] = np.full(m, 0.1)
    arrays.update(
        w1=rng.normal(0, 0.3, (h, 2 * k)),
        b1=rng.normal(0, 0.1, h),
        w2=rng.normal(0, 0.05, (m, h)),
        b2=np.zeros(m),
        mu=rng.normal(0, 0.1, 2 * k),
        sd=rng.uniform(0.5, 2.0, 2 * k),
    )
    tau = [0.0 if j % 3 == 0 else 0.15 for j in range(k)]  # s: a third of the inputs plain
    drift = [0.05 if j % 2 else 0.0 for j in range(k)]  # weight/s: half the inputs drift
    config = dict(w.config, hidden=h, lift_top=True, noise_band=16.0, rest_tau=tau,
                  rest_warm=0.2, rest_drift=drift)  # fmt: skip
    return TrackerMap(weights=MapWeights.build(config, arrays), names=ARKIT52, detail=0.5)


@pytest.mark.parametrize("which", ["shipped", "richer"])
def test_the_map_reference_computes_the_runtime_function(which):
    pytest.importorskip("torch")
    from faceclean.neural.map_reference import MapReference

    make = bench.tracker_map if which == "shipped" else _richer_map
    ours, ref = make(), MapReference(make())
    x, t = _walk(300, 3, 52, 5)
    ref.start(x[0])
    assert ours.step(x[0], t[0]).shape == (3, 52)
    for n in range(1, len(x)):
        want = ours.step(x[n], t[n])
        np.testing.assert_allclose(ref.step(x[n], t[n] - t[n - 1]), want, rtol=0, atol=1e-12)
    if which == "richer":  # the lift did act: some rise passed its knee; the band widened
        assert (ours._top > 0).any()
        assert (ours.weights.config["noise_band"] * ours._noise.s > ours._band).any()


def test_the_bench_runs_without_torch_and_says_so(tmp_path):
    out, md = tmp_path / "b.json", tmp_path / "b.md"
    code = f"""
        from faceclean.cli import main
        argv = ["bench", "--quick", "--no-pin", "--streams", "1,2"]
        raise SystemExit(main([*argv, "--json", {str(out)!r}, "--markdown", {str(md)!r}]))
    """
    proc = subprocess.run([sys.executable, "-c", NOT_INSTALLED + textwrap.dedent(code)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    result = json.loads(out.read_text())
    rows = {r["name"]: r for r in result["rows"]}
    assert result["reference"] is None and result["machine"]["torch"] is None
    assert not any("eager torch" in name for name in rows)
    assert result["references"].startswith("eager torch references not run")
    for name in ("lstm-numpy", "fc", bench.MAP):  # our rows, timed alone
        assert rows[name]["p50_us"] > 0 and set(rows[name]["throughput"]) == {"1", "2"}
    assert "No ratios: eager torch references not run" in md.read_text()


def test_the_bench_times_the_map_against_its_own_reference():
    pytest.importorskip("torch")
    result = bench.run(bench.Sizes.quick((1, 2)))
    rows = {r["name"]: r for r in result["rows"]}
    ours = rows[bench.MAP]
    assert ours["ref"] == "reference-map" and ours["p50_us"] > 0 and ours["hour_s"] > 0
    ref = next(r for r in result["rows"] if r["key"] == "reference-map")
    assert ref["name"] == "reference tracker map (eager torch)" and ref["p50_us"] > 0
    assert set(ref["throughput"]) == {1, 2} and ours["state_bytes"] > 0


@pytest.mark.parametrize("per_frame", [False, True])
@pytest.mark.parametrize("names", ["model order", "reordered"])
def test_fc_compiled_step_of_many_streams_gives_numpys_bits(per_frame, names):
    from faceclean.filters import make
    from faceclean.learned import jit

    if not jit.available():
        pytest.skip("numba not installed: FC steps in numpy only")
    cols = ARKIT52 if names == "model order" else ARKIT52[::-1]
    fast = make("fc", {"per_frame": per_frame}, names=cols)
    slow = make("fc", {"per_frame": per_frame}, names=cols)
    slow.jit_min_streams = 10**9  # numpy for every stream count
    x, t = _walk(150, 5, 52, 9)
    x[60:62] *= 40.0  # spikes: the features' clip
    t[90:] += 2e-10 * np.arange(5)  # streams a hair apart
    t[100, 0] = t[99, 0]  # a repeated time: the base rules' step
    x[110, 1, 3] = np.nan  # a lost value: rule 2
    for n in range(len(x)):
        a, b = fast.step(x[n], t[n]), slow.step(x[n], t[n])
        np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
        for u, v in zip(fast._state, slow._state, strict=True):
            np.testing.assert_array_equal(u.view(np.uint64), v.view(np.uint64))
    assert fast._jit is True and slow._jit is None  # the compiled kernels did run


@pytest.mark.parametrize("hidden", [(), (16, 8)])
def test_fc_compiled_step_of_any_depth_gives_numpys_bits(tmp_path, hidden):
    torch = pytest.importorskip("torch")
    from faceclean.learned import jit
    from faceclean.learned.derivative_net import FullyConnected
    from faceclean.neural import baselines

    if not jit.available():
        pytest.skip("numba not installed: FC steps in numpy only")
    torch.manual_seed(0)
    net = baselines.FCNet(52, hidden=hidden).eval()
    baselines.save_fc(net, tmp_path / "fc.npz", {"val_sources": ["x"]})
    fast, slow = (FullyConnected(model=tmp_path / "fc.npz") for _ in range(2))
    slow.jit_min_streams = 10**9
    x, t = _walk(60, 3, 52, 17)
    for n in range(len(x)):
        a, b = fast.step(x[n], t[n]), slow.step(x[n], t[n])
        np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
    assert fast._jit is True


def test_lstm_compiled_gates_of_many_streams_give_numpys_bits():
    from faceclean.learned import jit
    from faceclean.learned.lstm import Learned

    if not jit.available():
        pytest.skip("numba not installed: the LSTM steps in numpy only")
    fast, slow = Learned(kernel="numba"), Learned(kernel="numpy")
    S = fast.jit_max_streams + 3  # numpy's products, the compiled gates
    x, t = _walk(120, S, 52, 13)
    for n in range(len(x)):
        a, b = fast.step(x[n], t[n]), slow.step(x[n], t[n])
        np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
    for u, v in zip(fast._ws.state(), slow._ws.state(), strict=True):
        np.testing.assert_array_equal(u.view(np.uint32), v.view(np.uint32))
