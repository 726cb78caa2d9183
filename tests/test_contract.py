"""The contract every cleaner backend keeps (filters/base.py), run over every backend.

One parametrised suite over the table of tests/contract_backends.py (each method, the
LSTM's numpy and numba kernels, ONNX Runtime, the ``faceclean.Cleaner`` facade): causal,
reset forgets, constant in gives constant out, batch equals reset-then-step, the same
curve at 30/60/120 fps agrees, no NaN for any dt, t = 0.0 is a valid first time, (S, M)
streams equal S cleaners, the base time rules, names and channel order kept, a long
take's compiled whole-take clean equals reset-then-step. Each test
names its clause (``@pytest.mark.clause``); a backend that declares the clause
unsupported skips it, with its reason. Then the LSTM's runtimes agree on a real take.
"""

from __future__ import annotations

import numpy as np
import pytest
from contract_backends import BACKENDS, CLAUSES, COMPILED, Backend, Files
from helpers import steps

from faceclean import Animation
from faceclean.channels import ARKIT52
from faceclean.datasets import performer
from faceclean.filters import METHODS

M = len(ARKIT52)

# Constant in gives constant out: exact for the classical filters.
CONST_TOL = 1e-9
# Learned cleaners (trained on faces) get face-shaped contracts; measured with the
# shipped LSTM: held poses corrected by at most 0.054 (a raised brow; 0.018 on real
# takes), settled to 1e-8 a frame; 30 vs 120 fps on a
# synthetic face, mean 0.006 and max 0.10 (the max sits on blinks, whose 30 fps
# samples miss the peak).
LEARNED_CONST_OFFSET = 0.08
LEARNED_RATE_MEAN = 0.015
LEARNED_RATE_MAX = 0.2
# Channel order: the same numbers, up to float32 rounding in the learned runtimes.
ORDER_TOL = 1e-6


@pytest.fixture(scope="session")
def files(tmp_path_factory) -> Files:
    return Files(tmp_path_factory.mktemp("contract"))


@pytest.fixture(params=BACKENDS, ids=lambda b: b.id)
def backend(request) -> Backend:
    """The backend under test; skips, with the backend's reason, a clause it declares
    unsupported, or every clause when an optional package it runs on is missing."""
    b: Backend = request.param
    marker = request.node.get_closest_marker("clause")
    if marker is None or marker.args[0] not in CLAUSES:
        raise pytest.UsageError(f"{request.node.name}: mark it @pytest.mark.clause(NAME)")
    clause = marker.args[0]
    if b.absent():
        pytest.skip(f"{b.id}: {b.absent()}")
    if clause in b.skips():
        pytest.skip(f"{b.id} does not keep {clause!r}: {b.skips()[clause]}")
    return b


@pytest.fixture
def build(backend, files):
    """build(names=ARKIT52, streams=1): a fresh cleaner of the backend under test."""
    return lambda names=ARKIT52, streams=1: backend.make(files, tuple(names), streams)


def _curve(t: np.ndarray, seed: int = 0) -> np.ndarray:
    """(N, 52) smooth weights in [0.2, 0.8]: a sum of slow sines, per-channel phases."""
    return performer.sines(t, seed)


def _noisy(n: int, seed: int = 0, fps: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """(N,) jittered times (s) and (N, 52) noisy weights in [0, 1]."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.7, 1.3, n) / fps)
    x = np.clip(_curve(t, seed) + rng.normal(0, 0.02, (n, M)), 0.0, 1.0)
    return t, x


# --- the table itself ------------------------------------------------------------------


def test_the_table_covers_every_method_and_runtime():
    ids = [b.id for b in BACKENDS]
    assert len(set(ids)) == len(ids)
    assert set(METHODS) <= {b.method for b in BACKENDS if b.kind in ("method", "kernel")}
    assert {"method", "kernel", "onnx", "facade"} == {b.kind for b in BACKENDS}
    for b in BACKENDS:
        assert set(b.unsupported) <= set(CLAUSES), b.id
        assert all(reason.strip() for reason in b.skips().values()), b.id


# --- every backend ---------------------------------------------------------------------


def _held_face_settles(cleaner) -> None:
    """A learned cleaner may correct a held pose a little (it undoes tracker
    under-shoot and crosstalk), but a face held still settles: no drift, and a small
    correction. Poses are a face's (a synthetic performer's frames): 52 channels all
    half-active at once is no face, and a model of faces owes it nothing."""
    from faceclean.datasets import performer

    face = performer.perform(20.0, seed=2, fps=60.0)
    t = np.arange(600) / 60.0  # 10 s held
    for pose in face.values[::300]:
        y = cleaner.clean(Animation(t, np.tile(pose, (600, 1)), ARKIT52)).values
        assert np.abs(np.diff(y[-60:], axis=0)).max() < 1e-4  # settled in the last second
        assert np.abs(y[-1] - pose).max() < LEARNED_CONST_OFFSET


@pytest.mark.clause("constant")
def test_constant_in_constant_out(backend, build):
    cleaner = build()
    if backend.face:
        return _held_face_settles(cleaner)
    t = np.arange(240) / 60.0
    level = np.linspace(0.1, 0.9, M)
    y = cleaner.clean(Animation(t, np.tile(level, (240, 1)), ARKIT52)).values
    np.testing.assert_allclose(y, np.tile(level, (240, 1)), atol=CONST_TOL, rtol=0)


def _same_face_at_30_60_120_fps_agrees(cleaner) -> None:
    """A learned cleaner sees faces, not 52 sines at once: the same synthetic
    performance sampled at 30, 60 and 120 fps must agree at shared instants."""
    from faceclean.datasets import performer

    face = performer.perform(6.0, seed=1, fps=240.0)
    shared = {}
    for fps in (30, 60, 120):
        k = 240 // fps
        out = cleaner.clean(Animation(face.times[::k], face.values[::k], face.names)).values
        shared[fps] = out[:: fps // 30][15:-15]
    for fps in (30, 60):
        diff = np.abs(shared[fps] - shared[120])
        assert diff.mean() < LEARNED_RATE_MEAN, (fps, diff.mean())
        assert diff.max() < LEARNED_RATE_MAX, (fps, diff.max())


@pytest.mark.clause("rate")
def test_same_curve_at_30_60_120_fps_agrees(backend, build):
    cleaner = build()
    if backend.face:
        return _same_face_at_30_60_120_fps_agrees(cleaner)
    outs = {}
    for fps in (30, 60, 120):
        t = np.arange(int(4 * fps)) / fps  # 4 s
        outs[fps] = cleaner.clean(Animation(t, _curve(t), ARKIT52)).values
    # Shared instants: every 1/30 s, 0.5 s away from either end (warm-up, offline edges).
    shared = {fps: outs[fps][:: fps // 30][15:-15] for fps in outs}
    assert np.abs(shared[30] - shared[120]).max() < backend.rate_tol
    assert np.abs(shared[60] - shared[120]).max() < backend.rate_tol


@pytest.mark.clause("any_dt")
@pytest.mark.parametrize(
    "dts",
    [np.full(50, 1e-9), np.full(50, 1e6), np.geomspace(1e-7, 3.0, 50)],
    ids=["tiny", "huge", "mixed"],
)
def test_no_nan_for_any_dt(build, dts):
    t = np.concatenate([[0.0], np.cumsum(dts)])
    y = build().clean(Animation(t, _curve(t), ARKIT52)).values
    assert np.isfinite(y).all()
    assert (np.abs(y) < 10).all()


@pytest.mark.clause("t_zero")
def test_t_zero_is_a_valid_first_time(backend, build):
    t = np.arange(30) / 60.0  # starts at 0.0
    x = _curve(t)
    y = build().clean(Animation(t, x, ARKIT52)).values
    assert np.isfinite(y).all()
    if not backend.offline:
        np.testing.assert_allclose(y[0], x[0])  # first frame initialises from the input


@pytest.mark.clause("missing")
def test_missing_frames_stay_missing_and_change_nothing(build):
    t, x = _noisy(200, seed=3)
    gaps = np.zeros(200, bool)
    gaps[[0, 50, 51, 120]] = True  # includes the very first frame
    x_gap = x.copy()
    x_gap[gaps] = np.nan
    cleaner = build()
    y_gap = cleaner.clean(Animation(t, x_gap, ARKIT52)).values
    y_cut = cleaner.clean(Animation(t[~gaps], x[~gaps], ARKIT52)).values
    assert np.isnan(y_gap[gaps]).all()
    np.testing.assert_allclose(y_gap[~gaps], y_cut, rtol=0, atol=1e-12)


@pytest.mark.clause("names")
def test_clean_keeps_times_names_meta_and_its_input(build):
    t, x = _noisy(60, seed=7)
    anim = Animation(t, x, ARKIT52, {"format": "contract", "take": "seven"})
    before = anim.values.copy()
    out = build().clean(anim)
    assert out is not anim and out.values is not anim.values
    assert out.names == anim.names and out.meta == anim.meta
    np.testing.assert_array_equal(out.times, t)
    np.testing.assert_array_equal(anim.values, before)  # the input is not touched
    assert out.values.shape == x.shape and not np.allclose(out.values, x)


@pytest.mark.clause("order")
def test_channel_order_does_not_matter(build):
    perm = np.random.default_rng(7).permutation(M)
    names = [ARKIT52[j] for j in perm]
    t, x = _noisy(120, seed=8)
    ref = build().clean(Animation(t, x, ARKIT52)).values
    got = build(names=names).clean(Animation(t, x[:, perm], names)).values
    np.testing.assert_allclose(got, ref[:, perm], rtol=0, atol=ORDER_TOL)


@pytest.mark.clause("clean_rules")
def test_clean_holds_on_old_times_and_fills_nan_channels(build):
    t, x = _noisy(60, seed=9)
    t[30] = t[29]  # repeated
    t[40] = t[10]  # older
    x[45, 3] = np.nan  # one channel lost
    x[46, 7] = np.inf  # a tracker glitch
    x[47, 8] = -1e9  # an absurd value
    y = build().clean(Animation(t, x, ARKIT52)).values
    np.testing.assert_array_equal(y[30], y[29])
    np.testing.assert_array_equal(y[40], y[39])
    assert np.isfinite(y).all() and (np.abs(y) < 10).all()


@pytest.mark.clause("step_kind")
def test_step_follows_the_kind(backend, build):
    cleaner = build()
    t, x = _noisy(2, seed=12)
    if backend.offline:
        with pytest.raises(TypeError):
            cleaner.step(x[0], 0.0)
        return
    first = cleaner.step(x[0], 0.0)
    np.testing.assert_array_equal(first, x[0])  # the first frame initialises from the input
    assert not np.allclose(cleaner.step(x[1], 1 / 60), first)  # it advanced, did not hold


# --- streaming backends ----------------------------------------------------------------


@pytest.mark.clause("causal")
def test_causal(build):
    cleaner = build()
    t, x = _noisy(150, seed=1)
    future = x.copy()
    future[100:] = np.clip(1.0 - future[100:], 0, 1)
    y = steps(cleaner, t, x)
    cleaner.reset()
    y2 = steps(cleaner, t, future)
    np.testing.assert_array_equal(y[:100], y2[:100])
    assert not np.allclose(y[100:], y2[100:])


@pytest.mark.clause("reset")
def test_reset_forgets(build):
    cleaner = build()
    ta, xa = _noisy(80, seed=4)
    tb, xb = _noisy(80, seed=5)
    steps(cleaner, ta, xa)
    cleaner.reset()
    y = steps(cleaner, tb, xb)
    np.testing.assert_array_equal(y, steps(build(), tb, xb))


@pytest.mark.clause("batch")
def test_batch_equals_reset_then_step(build):
    cleaner = build()
    t, x = _noisy(150, seed=2)
    x[40] = np.nan
    x[60, 4] = np.nan  # a lost channel
    t[80] = t[79]  # a repeated time
    t[100:] += 1.0  # a pause past max_gap
    batch = cleaner.clean(Animation(t, x, ARKIT52)).values
    fresh = build()
    fresh.step(np.full(M, 0.3), 0.0)  # dirty state: clean() must reset it
    batch2 = fresh.clean(Animation(t, x, ARKIT52)).values
    cleaner.reset()
    streamed = steps(cleaner, t, x)
    streamed[40] = np.nan  # clean() leaves missing frames NaN; step() holds
    # the tracker map's compiled take (on whenever numba is loaded in this process, as any
    # earlier fit or long take leaves it) sums its products in its own order: 1e-12, as the
    # whole-take clause allows it; every other backend is bit for bit
    tol = 1e-12 if getattr(cleaner, "name", "") == "tracker-map" else 0.0
    np.testing.assert_allclose(batch, streamed, rtol=0.0, atol=tol)
    np.testing.assert_allclose(batch2, streamed, rtol=0.0, atol=tol)


@pytest.mark.clause("streams")
def test_streams_equal_independent_cleaners(backend, build):
    s, n = 3, 90
    data = [_noisy(n, seed=10 + i, fps=30 + 30 * i) for i in range(s)]
    t = np.stack([d[0] for d in data], axis=1)  # (N, S)
    x = np.stack([d[1] for d in data], axis=1)  # (N, S, M)
    x[20, 1] = np.nan  # stream 1 loses a frame
    x[30, 2, 5] = np.nan  # stream 2 loses one channel
    t[25, 2] = np.nan  # stream 2 has a frame without a time
    t[40, 1] = t[39, 1]  # stream 1 repeats a time
    t[60:, 0] += 2.0  # stream 0 pauses past max_gap
    together = build(streams=s)
    y_all = np.array([together.step(x[i], t[i]) for i in range(n)])  # (N, S, M)
    for j in range(s):
        alone = build()
        y = np.array([alone.step(x[i, j], t[i, j]) for i in range(n)])
        np.testing.assert_allclose(y_all[:, j], y, rtol=0, atol=backend.streams_tol)


@pytest.mark.clause("time_rules")
def test_time_rules(build):
    cleaner = build()
    t, x = _noisy(40, seed=6)
    nan = np.full(M, np.nan)
    assert np.isnan(cleaner.step(nan, 0.0)).all()  # missing before any frame: NaN
    first = x[0].copy()
    first[[2, 9]] = np.nan, 1e9  # lost and absurd before any frame: 0
    want = x[0].copy()
    want[[2, 9]] = 0.0
    np.testing.assert_array_equal(cleaner.step(first, t[0]), want)
    cleaner.reset()
    y = steps(cleaner, t[:20], x[:20])
    last = y[-1]
    # Missing frame (all NaN, or t NaN): last output, state unchanged.
    np.testing.assert_array_equal(cleaner.step(nan, t[20]), last)
    np.testing.assert_array_equal(cleaner.step(x[20], float("nan")), last)
    # Repeated or older timestamp: last output, state unchanged.
    np.testing.assert_array_equal(cleaner.step(x[20], t[19]), last)
    np.testing.assert_array_equal(cleaner.step(x[20], t[5]), last)
    held = cleaner.step(x[20], t[20])
    ref = build()
    steps(ref, t[:20], x[:20])
    np.testing.assert_allclose(held, ref.step(x[20], t[20]), rtol=0, atol=1e-12)
    # A NaN channel takes its last output.
    part = x[21].copy()
    part[3] = np.nan
    assert np.isfinite(cleaner.step(part, t[21])).all()
    # A pause longer than max_gap restarts from the input.
    np.testing.assert_array_equal(cleaner.step(x[22], t[21] + 10.0), x[22])


@pytest.mark.clause("whole_take")
def test_whole_take_equals_reset_then_step(backend, build, monkeypatch):
    """A take long enough for the compiled whole-take path (filters/compiled.py
    ``for_take``, its threshold lowered to this take), with every kind of frame the time
    rules know, one of them on a block's edge (filters/base.py BLOCK)."""
    from faceclean.filters import base, compiled

    if not compiled.enable(warm=False):
        pytest.skip("numba not installed: the numpy path is the batch clause's")
    monkeypatch.setattr(compiled, "WHOLE_TAKE_FRAMES", 0)
    asked = []
    kernel = compiled._kernel
    monkeypatch.setattr(compiled, "_kernel", lambda name: asked.append(name) or kernel(name))
    n = base.BLOCK + 300
    t, x = _noisy(n, seed=8)
    x[40] = np.nan  # a missing frame
    x[60, 4], x[61, 9] = np.nan, 1e9  # a lost and an absurd value
    t[80] = t[79]  # a repeated time
    t[90] = t[89] - 0.01  # a step back
    t[base.BLOCK] = t[base.BLOCK - 1]  # a repeat on the block's edge
    t[base.BLOCK + 100 :] += 1.0  # a pause past max_gap
    whole = build().clean(Animation(t, x, ARKIT52)).values
    streamed = steps(build(), t, x)
    streamed[40] = np.nan  # clean() leaves missing frames NaN; step() holds
    assert np.array_equal(np.isnan(whole), np.isnan(streamed))
    np.testing.assert_allclose(whole, streamed, rtol=0, atol=backend.whole_tol)
    assert bool(asked) == (backend.method in COMPILED), asked


# --- the LSTM's runtimes agree -----------------------------------------------------------

AGREE_TOL = 2e-5  # as tests/test_parity.py: float32 runtimes, closed loop, real take
RUNTIMES = [b for b in BACKENDS if b.method == "lstm"]  # kernels, ONNX, the facade


@pytest.fixture(scope="module")
def real_take(takes_root) -> Animation:
    """The shortest take of settings.takes_dir() with all 52 ARKit channels, at most
    600 frames of it (tracking-loss rows kept)."""
    from faceclean import load
    from faceclean.datasets.dataset import SUFFIXES

    root = takes_root
    paths = [p for p in root.rglob("*") if p.suffix.lower() in SUFFIXES and p.is_file()]
    for p in sorted(paths, key=lambda p: (p.stat().st_size, str(p))):
        anim = load(p)
        values, present = anim.arkit()
        if present.all():
            return Animation.from_arkit(anim.times[:600], values[:600])
    pytest.skip(f"no take under {root} has all 52 ARKit channels")


@pytest.fixture(scope="module")
def reference(real_take) -> np.ndarray:
    """(N, 52) the numpy kernel's cleaned take: what every other runtime must give."""
    from faceclean.filters import make

    y = make("lstm", {"kernel": "numpy"}).clean(real_take).values
    v = real_take.valid
    assert np.abs(y - real_take.values)[v].max() > 1e-3  # the network does something
    return y


@pytest.mark.parametrize("runtime", RUNTIMES[1:], ids=lambda b: b.id)
def test_lstm_runtimes_agree_on_a_real_take(runtime, files, real_take, reference):
    assert RUNTIMES[0].id == "lstm[numpy]"
    if runtime.absent():
        pytest.skip(f"{runtime.id}: {runtime.absent()}")
    y = runtime.make(files, ARKIT52, 1).clean(real_take).values
    v = real_take.valid
    assert np.isnan(y[~v]).all()
    np.testing.assert_allclose(y[v], reference[v], rtol=0, atol=AGREE_TOL)


@pytest.mark.parametrize("runtime", RUNTIMES, ids=lambda b: b.id)
def test_lstm_runtimes_agree_on_three_streams_of_a_real_take(runtime, files, real_take):
    """Three faces stepped together, the take from frames 0, 40 and 80: each stream's
    output is the reference's cleaning of that part of the take."""
    if runtime.absent():
        pytest.skip(f"{runtime.id}: {runtime.absent()}")
    from faceclean.filters import make

    starts, n = (0, 40, 80), len(real_take.times) - 80
    t = np.stack([real_take.times[k : k + n] for k in starts], axis=1)  # (N, S) s
    x = np.stack([real_take.values[k : k + n] for k in starts], axis=1)  # (N, S, M)
    cleaner = runtime.make(files, ARKIT52, len(starts))
    y = np.array([cleaner.step(x[i], t[i]) for i in range(n)])  # (N, S, M)
    for j in range(len(starts)):
        part = Animation(t[:, j], x[:, j], ARKIT52)
        ref = make("lstm", {"kernel": "numpy"}).clean(part).values
        v = part.valid
        np.testing.assert_allclose(y[v, j], ref[v], rtol=0, atol=AGREE_TOL)


def test_numba_off_switch_reaches_the_lstm_kernel_too():
    """FACECLEAN_NUMBA=0 (filters/compiled.py) keeps learned/jit.py's kernels off as well:
    the LSTM runs its numpy kernel, and numba is never imported."""
    import os
    import subprocess
    import sys

    code = (
        "import sys; from faceclean.filters import make; "
        "print(make('lstm', {}).kernel, 'numba' in sys.modules)"
    )
    env = {**os.environ, "FACECLEAN_NUMBA": "0"}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, check=True)  # fmt: skip
    assert done.stdout.split() == ["numpy", "False"]
