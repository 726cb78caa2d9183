"""The torch-free learned runtime (learned/lstm.py) and the Cleaner facade.

The numpy step is checked against a float64 transcription of SPEC section 2 written
here from the spec alone; the compiled kernel against the same; the fast path against
the base class's generic time rules.
"""

from __future__ import annotations

import functools
import json
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from faceclean import Animation, Cleaner, FacecleanError
from faceclean.channels import ARKIT52
from faceclean.filters import make
from faceclean.learned import jit
from faceclean.learned.checkpoint import LSTMWeights
from faceclean.learned.lstm import Learned

KERNELS = ["numpy"] + (["numba"] if jit.available() else [])
TOL = 1e-5  # float32 runtime vs float64 reference, over a few hundred closed-loop steps
OUTPUTS = ["additive", "gated", "rate"]  # output heads: x_c + b, or g x_c + b


@functools.cache
def _weights(output: str) -> LSTMWeights:
    w = LSTMWeights.random(ARKIT52, seed=3, output=output)
    # A livelier head than the init, so that the network's correction is visible.
    return LSTMWeights.from_arrays({**w.to_arrays(), "out_scale": np.full(52, 4.0, np.float32)})


@pytest.fixture(scope="module")
def weights() -> LSTMWeights:
    return _weights("additive")


@pytest.fixture(scope="module")
def clip() -> tuple[np.ndarray, np.ndarray]:
    """(N,) irregular times (s) and (N, 52) random-walk values in [0, 1]."""
    rng = np.random.default_rng(0)
    n = 240
    t = np.cumsum(rng.uniform(0.008, 0.04, n))
    x = np.clip(0.4 + np.cumsum(rng.normal(0, 0.03, (n, 52)), axis=0), 0, 1)
    return t, x


def spec_reference(w: LSTMWeights, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """SPEC section 2 (K = 1) in float64, one stream, every frame advancing."""
    M, H, L = 52, w.hidden, w.layers
    y, d = x[0].copy(), np.zeros(M)
    h, c = [np.zeros(H) for _ in range(L)], [np.zeros(H) for _ in range(L)]
    out = [y.copy()]
    sig = lambda a: 1 / (1 + np.exp(-a))  # noqa: E731
    for n in range(1, len(t)):
        dt = t[n] - t[n - 1]
        xc = (x[n] - y) / dt
        u = (np.concatenate([y, d, xc]) - w.feat_mean) / w.feat_std
        for i in range(L):
            a = w.w_ih[i] @ u + w.w_hh[i] @ h[i] + w.b_ih[i] + w.b_hh[i]
            gi, gf, gg, go = np.split(a, 4)
            c[i] = sig(gf) * c[i] + sig(gi) * np.tanh(gg)
            h[i] = sig(go) * np.tanh(c[i])
            u = h[i] if i == 0 else h[i] + u
        head = w.head_w @ u + w.head_b
        if w.gated:  # rows: gain logits a, then corrections b
            d = (1 + np.tanh(head[:M])) * xc + w.out_scale * head[M:]
        elif w.output == "rate":  # one-pole gain, time constant 2 ms e^a
            gain = 1 - np.exp(-dt / (0.002 * np.exp(np.clip(head[:M], -15, 15))))
            d = gain * xc + w.out_scale * head[M:]
        else:
            d = xc + w.out_scale * head
        y = np.clip(y + dt * d, 0.0, 1.0)
        out.append(y.copy())
    return np.array(out)


@pytest.mark.parametrize("output", OUTPUTS)
@pytest.mark.parametrize("kernel", KERNELS)
def test_step_matches_the_spec(clip, kernel, output):
    t, x = clip
    weights = _weights(output)
    ref = spec_reference(weights, t, x)
    c = Learned(weights=weights, kernel=kernel)
    got = np.array([c.step(x[n], t[n]) for n in range(len(t))])
    assert got.dtype == np.float64 and got.shape == x.shape
    assert np.abs(ref - x).max() > 1e-2  # the network really corrects something
    np.testing.assert_allclose(got, ref, atol=TOL)


@pytest.mark.parametrize("output", OUTPUTS)
@pytest.mark.parametrize("kernel", KERNELS)
def test_zero_network_follows_its_input(clip, kernel, output):
    t, x = clip
    w = LSTMWeights.random(ARKIT52, seed=1, gain=0.0, output=output)  # gated: gain 1
    got = Learned(weights=w, kernel=kernel).clean(Animation.from_arkit(t, x * 1.2 - 0.1)).values
    # rate: a 2 ms one-pole low-pass, gain >= 1 - exp(-8 ms / 2 ms) here
    tol = 5e-3 if output == "rate" else 1e-6
    np.testing.assert_allclose(got, np.clip(x * 1.2 - 0.1, 0, 1), atol=tol)


def _events(S: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Times (n, S) and frames (n, S, 52) with every time rule hit in some stream."""
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.01, 0.03, (n, S)), axis=0)
    t[0, 0] = 0.0  # t == 0.0 is a valid time
    x = rng.uniform(0, 1, (n, S, 52))
    x[10, 0] = np.nan  # missing frame
    x[12, 1, 3:7] = np.nan  # NaN channels
    t[15:, 2] += 1.0  # a gap: restart
    t[20, 0] = t[19, 0]  # repeated timestamp
    t[25, 1] = np.nan  # missing time
    x[30, 2, 0] = np.inf
    return t, x


@pytest.mark.parametrize("kernel", KERNELS)
def test_fast_path_equals_generic_rules(weights, kernel):
    S, n = 3, 40
    t, x = _events(S, n)
    fast, slow = (Learned(weights=weights, kernel=kernel) for _ in range(2))
    fast.jit_max_streams = slow.jit_max_streams = 64  # the compiled kernel for 3 streams too
    for i in range(n):
        a = fast.step(x[i], t[i])
        b = slow._generic_step(x[i], t[i])  # the base class's rules, no fast path
        np.testing.assert_array_equal(a, b)
    # and one stream (M,) with scalar times
    fast.reset(), slow.reset()
    for i in range(n):
        np.testing.assert_array_equal(
            fast.step(x[i, 0], t[i, 0]), slow._generic_step(x[i, 0], t[i, 0])
        )


@pytest.mark.parametrize("kernel", KERNELS)
def test_clean_equals_stepping_every_frame(weights, clip, kernel):
    t, x = clip
    t, x = t.copy(), x.copy()
    x[30] = np.nan  # missing frame
    x[40, 2:5] = np.nan  # NaN channels
    t[60] = t[59]  # repeated timestamp (held), then the next frame follows it
    t[80] = t[79] - 0.01  # backwards: held
    t[90] = t[89] + 1e-13  # within MIN_DT of the last: held
    t[100:] += 2.0  # a pause: restart
    x[70, 7] = np.nan
    nan = Learned(weights=weights, kernel=kernel).clean(Animation.from_arkit(t, x)).values
    x[70, 7] = 1e7  # absurd: rule 2 takes it as non-finite, on every path
    anim = Animation.from_arkit(t, x)
    fast = Learned(weights=weights, kernel=kernel).clean(anim).values
    stepped = Learned(weights=weights, kernel=kernel)
    slow = super(Learned, stepped).clean(anim).values  # the base loop: step every frame
    np.testing.assert_array_equal(fast, slow)
    np.testing.assert_array_equal(fast, nan)
    assert np.isnan(fast[30]).all() and np.isfinite(np.delete(fast, 30, 0)).all()


def test_time_rules(weights):
    c = Learned(weights=weights)
    x0, x1 = np.full(52, 0.2), np.full(52, 0.6)
    np.testing.assert_allclose(c.step(x0, 0.0), x0, atol=1e-7)  # first frame passes
    y1 = c.step(x1, 0.02)
    assert not np.allclose(y1, x0)
    np.testing.assert_array_equal(c.step(x0, 0.02), y1)  # repeated t holds
    np.testing.assert_array_equal(c.step(np.full(52, np.nan), 0.03), y1)  # missing holds
    np.testing.assert_allclose(c.step(x0, 5.0), x0, atol=1e-7)  # long gap restarts


@pytest.mark.parametrize("kernel", KERNELS)
def test_streams_together_equal_streams_alone(weights, kernel):
    S, n = 5, 40
    t, x = _events(S, n)
    x = np.nan_to_num(x, nan=0.5, posinf=0.5)
    t = np.cumsum(np.full((n, S), 0.015), axis=0) + np.arange(S) * 0.003
    together = Learned(weights=weights, kernel=kernel)
    together.jit_max_streams = 64
    got = np.array([together.step(x[i], t[i]) for i in range(n)])
    for s in range(S):
        alone = Learned(weights=weights, kernel=kernel)
        one = np.array([alone.step(x[i, s], t[i, s]) for i in range(n)])
        np.testing.assert_allclose(got[:, s], one, atol=1e-6)


def test_channels_map_by_name(weights, clip):
    t, x = clip
    t, x = t[:60], x[:60]
    keep = [j for j in range(52) if j not in (5, 17, 40)]  # the input lacks 3 channels
    order = np.random.default_rng(1).permutation(keep)
    names = [ARKIT52[j].upper() for j in order] + ["HeadYaw", "foo"]  # any spelling
    extra = np.random.default_rng(2).uniform(-3, 3, (60, 2))
    got = Learned(weights=weights, names=names).clean(
        Animation(t, np.hstack([x[:, order], extra]), names)
    )
    np.testing.assert_array_equal(got.values[:, -2:], extra)  # extras pass through
    # Reference: the model in its own order, the lacking channels fed its last output.
    ref, y = Learned(weights=weights), np.zeros(52)
    want = []
    for n in range(60):
        frame = x[n].copy()
        frame[[5, 17, 40]] = y[[5, 17, 40]]
        y = ref.step(frame, t[n])
        want.append(y[order])
    np.testing.assert_allclose(got.values[:, :-2], np.array(want), atol=1e-7)


def _step_peaks(kernel: str, output: str, control: bool) -> dict[int, tuple[int, int]]:
    """{S: (peak bytes, bound)} over 58 warm steps of S streams (the control: plus a
    temporary of the bound's size each step).

    tracemalloc counts every thread of the process, and the compiled step releases the
    GIL: run this where no other thread allocates (``_isolated_peaks``).
    """
    out = {}
    for S in (1, 16):
        c = Learned(weights=_weights(output), kernel=kernel)
        c.jit_max_streams = 64  # the chosen kernel at every stream count
        x = np.full((S, 52), 0.3) if S > 1 else np.full(52, 0.3)
        c.step(x, np.zeros(S) if S > 1 else 0.0)
        y = c.step(x, np.full(S, 0.01) if S > 1 else 0.01)  # warm (compiles, allocates)
        bound = 2 * y.nbytes + 2048  # the returned frame and the one before it, not the state
        tracemalloc.start()
        for i in range(2, 60):
            t = 0.01 * i
            scratch = np.empty(bound if control else 0, np.uint8)  # the control's temporary
            y = c.step(x, np.full(S, t) if S > 1 else t)
            del scratch
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        out[S] = (peak, bound)
    return out


@functools.cache
def _isolated_peaks(control: bool = False) -> dict[str, dict[int, tuple[int, int]]]:
    """``_step_peaks`` for every kernel and head, in a fresh interpreter with one thread.

    In the test process pytest-xdist's I/O thread (or any other) may allocate during the
    measurement on a loaded machine; a child process runs the main thread alone.
    """
    code = (
        "import json, sys, threading\n"
        f"sys.path.insert(0, {str(Path(__file__).parent)!r})\n"
        "from test_runtime import KERNELS, OUTPUTS, _step_peaks\n"
        f"peaks = {{f'{{k}}-{{o}}': _step_peaks(k, o, {control})\n"
        "         for k in KERNELS for o in OUTPUTS}\n"
        "assert threading.active_count() == 1, threading.enumerate()\n"
        "print(json.dumps(peaks))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    peaks = json.loads(proc.stdout.splitlines()[-1])
    return {k: {int(S): tuple(v) for S, v in d.items()} for k, d in peaks.items()}


@pytest.mark.parametrize("output", OUTPUTS)
@pytest.mark.parametrize("kernel", KERNELS)
def test_fast_step_allocates_only_its_output(kernel, output):
    for S, (peak, bound) in _isolated_peaks()[f"{kernel}-{output}"].items():
        assert peak < bound, (S, peak, bound)


def test_the_allocation_measure_sees_a_temporary():
    """The control: a step that also allocates the bound's size in bytes fails the bound."""
    for name, peaks in _isolated_peaks(control=True).items():
        for S, (peak, bound) in peaks.items():
            assert peak >= bound, (name, S, peak, bound)


def test_state_is_a_few_kilobytes(weights):
    assert Learned(weights=weights).state_bytes == 4 * (2 * 52 + 2 * 2 * 128)  # 2464


def test_bad_checkpoints(tmp_path, weights):
    arrays = weights.to_arrays()
    cases = {
        "text.npz": b"not a zip",
        "nokey.npz": {k: v for k, v in arrays.items() if k != "head.w"},
        "shape.npz": {**arrays, "feat_std": np.ones(3, np.float32)},
        "format.npz": {**arrays, "config": np.array('{"format": "other"}')},
        "std.npz": {**arrays, "feat_std": np.zeros(156, np.float32)},
        "head.npz": {**_weights("gated").to_arrays(), "head.w": arrays["head.w"]},  # 52 rows
        "output.npz": {
            **arrays,
            "config": np.array(json.dumps({**weights.config, "output": "multiplicative"})),
        },
        # one name for every channel: it cleaned nothing and said it cleaned (red team)
        "twice.npz": {
            **arrays,
            "config": np.array(
                json.dumps({**weights.config, "channels": ["x"] * len(weights.channels)})
            ),
        },
    }
    for name, content in cases.items():
        p = tmp_path / name
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            np.savez(p, **content)
        with pytest.raises(FacecleanError) as e:
            Learned(p)
        assert "\n" not in str(e.value)
        assert name != "twice.npz" or "channel 'x' is listed twice" in str(e.value)
    with pytest.raises(FacecleanError):
        Learned(tmp_path / "absent.npz")


def test_checkpoint_roundtrip_and_make(tmp_path, weights, clip):
    p = tmp_path / "m.npz"
    weights.save(p)
    t, x = clip
    a = make("lstm", {"model": p}).clean(Animation.from_arkit(t[:50], x[:50])).values
    b = Learned(weights=weights).clean(Animation.from_arkit(t[:50], x[:50])).values
    np.testing.assert_array_equal(a, b)


@pytest.mark.skipif(not jit.available(), reason="numba not installed")
def test_compiled_tanh_accuracy():
    from numba import njit

    tanh = jit._tanh

    @njit
    def apply(a):
        out = np.empty_like(a)
        for i in range(a.size):
            out[i] = tanh(a[i])
        return out

    a = np.linspace(-20, 20, 400_001).astype(np.float32)
    err = np.abs(apply(a) - np.tanh(a.astype(np.float64)))
    assert err.max() < 4e-7  # about 5 float32 ulps near 1


# -- the facade ------------------------------------------------------------------------------


def test_cleaner_load_and_step(tmp_path, weights, clip):
    p = tmp_path / "m.npz"
    weights.save(p)
    t, x = clip
    one = Cleaner.load(p)
    many = Cleaner.load(p, streams=4)
    for n in range(20):
        y = one.step(x[n], t[n])
        ys = many.step(np.tile(x[n], (4, 1)), np.full(4, t[n]))
        assert y.shape == (52,) and ys.shape == (4, 52)
        np.testing.assert_allclose(ys, np.tile(y, (4, 1)), atol=1e-6)
    with pytest.raises(FacecleanError, match="frame shape"):
        many.step(x[0], t[0])
    with pytest.raises(FacecleanError, match="t shape"):
        many.step(np.tile(x[0], (4, 1)), 0.0)


def test_cleaner_clean_keeps_other_columns(tmp_path, weights, clip):
    p = tmp_path / "m.npz"
    weights.save(p)
    t, x = clip
    names = list(ARKIT52) + ["HeadYaw"]
    values = np.hstack([x, np.linspace(-1, 1, len(t))[:, None]])
    values[7] = np.nan  # a missing frame stays missing
    anim = Animation(t, values, names)
    got = Cleaner.load(p).clean(anim)
    np.testing.assert_array_equal(got.values[:, -1], values[:, -1])
    assert np.isnan(got.values[7]).all() and not np.isnan(np.delete(got.values, 7, 0)).any()
    np.testing.assert_array_equal(anim.values, values)  # input untouched
    ref = Learned(weights=weights).clean(Animation.from_arkit(t, values[:, :52])).values
    np.testing.assert_array_equal(got.values[:, :52], ref)


def test_cleaner_classical_and_errors(tmp_path):
    assert Cleaner.load("kalman").step(np.full(52, 0.5), 0.0).shape == (52,)
    gauss = Cleaner.load("gaussian")
    assert gauss.offline
    with pytest.raises(FacecleanError, match="offline"):
        gauss.step(np.zeros(52), 0.0)
    default = Cleaner.load()  # the shipped model
    assert default.step(np.full(52, 0.5), 0.0).shape == (52,)
    assert default.source.startswith("adaptive")
    assert "lstm" in Cleaner.load("lstm").source  # the paper's, a shipped baseline
    for bad, msg in [
        ("no-such-method", "no model, preset or method"),
        (tmp_path / "x.npz", "no such model file"),
    ]:
        with pytest.raises(FacecleanError, match=msg):
            Cleaner.load(bad)
    with pytest.raises(FacecleanError, match="backend"):
        Cleaner.load("kalman", backend="gpu")
    with pytest.raises(FacecleanError, match="learned models only"):
        Cleaner.load("kalman", backend="onnx")
    with pytest.raises(FacecleanError, match="streams"):
        Cleaner.load("kalman", streams=0)


# -- the benchmark (structure only: tiny sizes, no timing assertions) --------------------


def test_bench_quick_structure(tmp_path, capsys):
    import json

    from faceclean.cli import main

    out, md = tmp_path / "b.json", tmp_path / "B.md"
    md.write_text("# Title\n\nprose\n<!-- bench:begin -->\nold\n<!-- bench:end -->\ntail\n")
    args = ["bench", "--quick", "--no-pin", "--streams", "1,2", "--json", str(out)]
    assert main([*args, "--markdown", str(md)]) == 0
    result = json.loads(out.read_text())
    rows = {r["name"]: r for r in result["rows"]}
    assert {"ema", "one-euro", "kalman", "lstm-numpy", "gaussian", "savgol"} <= set(rows)
    for name in ("ema", "lstm-numpy"):
        assert rows[name]["p99_us"] >= rows[name]["p50_us"] > 0
        assert set(rows[name]["throughput"]) == {"1", "2"}
        assert rows[name]["hour_s"] > 0 and rows[name]["state_bytes"] > 0
    assert rows["lstm-numpy"]["state_bytes"] == 2464 + 52 * 8 + 8
    assert rows["gaussian"]["p50_us"] is None and rows["gaussian"]["hour_s"] > 0
    text = md.read_text()
    assert text.startswith("# Title\n\nprose\n") and text.endswith("tail\n") and "old" not in text
    assert "| lstm-numpy |" in text and "Machine:" in text
    shown = capsys.readouterr().out
    assert "| lstm-numpy |" in shown  # and the files, the one that was there said replaced
    assert f"\nwrote {out}\n" in shown and f"\nreplaced {md}\n" in shown
    # issue 19: the shipped default has its own reference, eager torch on its network
    if result["reference"] is not None:
        default = rows["default (adaptive)"]
        assert default["ref"] == "reference-adaptive" and "inert network" in default["note"]
        ref = rows["reference adaptive (eager torch)"]
        assert ref["key"] == "reference-adaptive" and ref["p50_us"] > 0
        line = next(ln for ln in text.splitlines() if ln.startswith("| default (adaptive) |"))
        ratio = default["p50_us"] / ref["p50_us"]
        assert f"{default['p50_us']:.1f} ({ratio:.2f}x)" in line  # its ratio, to its reference
