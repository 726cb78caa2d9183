"""The learned adaptive filter: runtime = torch model, zero network = tuned One Euro,
a held pose stays put, fine-tuning never writes a worse model."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import first_take

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.filters import make
from faceclean.learned.adaptive import Adaptive, AdaptiveWeights, mirror_index

torch = pytest.importorskip("torch")

from faceclean.neural.adaptive import AdaptiveConfig, AdaptiveNet, score, train  # noqa: E402


def _wobbly(seed: int = 0, n: int = 150) -> Animation:
    """A face moving on irregular times (8-40 ms steps) with noise, values in [0, 1]."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.008, 0.04, n))
    t -= t[0]
    phase = np.arange(52)
    x = 0.5 + 0.3 * np.sin(2.0 * t[:, None] + phase) + 0.04 * rng.standard_normal((n, 52))
    return Animation.from_arkit(t, np.clip(x, 0.0, 1.0))


@pytest.fixture(scope="module")
def real_pose() -> np.ndarray:
    """A real iPhone frame (52,), a third of the way into a neurosync take."""
    from faceclean.io import load

    x, _ = load(first_take("neurosync")).arkit()
    x = x[np.isfinite(x).all(1)]
    return x[len(x) // 3]


def _random_net(seed: int = 1) -> AdaptiveNet:
    torch.manual_seed(seed)
    net = AdaptiveNet(ARKIT52, hidden=8, embed=4)
    with torch.no_grad():
        net.head.weight.normal_(0.0, 0.5)
        net.head.bias.normal_(0.0, 1.0)
        net.boost.normal_(0.0, 0.5)
    return net


def test_numpy_runtime_matches_the_torch_model():
    net = _random_net()
    anim = _wobbly()
    with torch.no_grad():
        x = torch.tensor(anim.values[None], dtype=torch.float32)
        t = torch.tensor(anim.times[None], dtype=torch.float32)
        expected = net(x, t)[0].numpy()
    got = Adaptive(weights=net.weights()).clean(anim).values
    assert np.abs(got - expected).max() < 2e-5
    assert np.abs(got - anim.values).max() > 1e-3  # it did filter


def test_zero_network_is_the_tuned_one_euro():
    anim = _wobbly(3)
    net = AdaptiveNet(ARKIT52, hidden=8, embed=4)
    with torch.no_grad():
        net.head.bias.copy_(torch.tensor([0.0, -60.0]))  # slope share sigmoid(-60) = 0
    got = Adaptive(weights=net.weights()).clean(anim).values
    want = make("one-euro", names=ARKIT52).clean(anim).values
    assert np.abs(got - want).max() < 1e-5


def test_streams_are_independent_and_match_single_streams():
    w = _random_net().weights()
    a, b = _wobbly(4, 60), _wobbly(5, 60)
    batch = Adaptive(weights=w)
    ys = np.stack(
        [
            batch.step(np.stack([a.values[i], b.values[i]]), [a.times[i], b.times[i]])
            for i in range(60)
        ]
    )
    assert np.allclose(ys[:, 0], Adaptive(weights=w).clean(a).values, atol=1e-12)
    assert np.allclose(ys[:, 1], Adaptive(weights=w).clean(b).values, atol=1e-12)


@pytest.mark.parametrize("fps", [24.0, 60.0, 120.0])
def test_a_held_real_pose_stays_exactly_where_the_tracker_puts_it(real_pose, fps):
    """Do no harm: a constant pose in, the same pose out (tolerance 1e-9), any rate."""
    for w in (_random_net().weights(), AdaptiveWeights.load(_shipped())):
        t = np.arange(int(3 * fps)) / fps
        y = Adaptive(weights=w).clean(
            Animation.from_arkit(t, np.repeat(real_pose[None], len(t), 0))
        )
        assert np.abs(y.values - real_pose).max() < 1e-9


def test_a_noisy_held_pose_keeps_its_mean_level(real_pose):
    """Zero-mean tracker noise on a held pose: the output's mean stays at the pose."""
    rng = np.random.default_rng(8)
    t = np.arange(1200) / 60.0
    x = np.clip(real_pose + 0.01 * rng.standard_normal((1200, 52)), 0.0, 1.0)
    y = Adaptive(weights=AdaptiveWeights.load(_shipped())).clean(Animation.from_arkit(t, x)).values
    assert np.abs(y[60:].mean(0) - x[60:].mean(0)).max() < 0.003


def test_mirror_pairs_left_and_right():
    m = mirror_index(ARKIT52)
    i = ARKIT52.index("eyeBlinkLeft")
    assert ARKIT52[m[i]] == "eyeBlinkRight" and m[m[i]] == i
    assert m[ARKIT52.index("jawOpen")] == ARKIT52.index("jawOpen")


def test_checkpoint_round_trip_and_refusals(tmp_path):
    w = _random_net().weights()
    w.save(tmp_path / "m.npz")
    back = AdaptiveWeights.load(tmp_path / "m.npz")
    for k, v in w.arrays.items():
        assert np.allclose(back.arrays[k], v, atol=1e-6)
    arrays = dict(w.arrays, **{"head.b": np.array([np.nan, 0.0])})
    with pytest.raises(FacecleanError, match="non-finite"):
        AdaptiveWeights.from_arrays(w.config, arrays)
    with pytest.raises(FacecleanError, match="missing"):
        AdaptiveWeights.from_arrays(w.config, {k: v for k, v in w.arrays.items() if k != "emb"})


def test_fine_tuning_never_writes_a_worse_model(tmp_path):
    """A run that can only make things worse (a huge learning rate) writes the start."""
    start = tmp_path / "start.npz"
    AdaptiveWeights.load(_shipped()).save(start)
    out = tmp_path / "tuned.npz"
    cfg = AdaptiveConfig(
        out=str(out), val_sources=("jmtechart",), epochs=1, max_batches=2, lr=5.0,
        synthetic_minutes=0.0, resume=str(start), preset="mixed", batch=4,
    )  # fmt: skip
    record = train(cfg)
    from faceclean.datasets import dataset
    from faceclean.evaluation import harness

    _, val = dataset.split(dataset.load_takes(), val_sources=("jmtechart",))
    streams = harness.streams(val)
    assert score(AdaptiveWeights.load(out), streams) <= score(AdaptiveWeights.load(start), streams)
    assert record.get("start") or record["score"] <= score(AdaptiveWeights.load(start), streams)


def _shipped():
    from faceclean.settings import MODELS

    return MODELS / "default.npz"


# -- issue 19 section 5: a network whose output cannot change the result costs nothing --


def _full(cleaner):
    """The same cleaner forced through the whole step (the GRU core run)."""
    cleaner.inert = False
    return cleaner


def test_the_shipped_default_is_inert_and_its_fast_step_gives_the_same_numbers():
    fast, full = Adaptive(), _full(Adaptive())
    assert fast.inert and fast.state_bytes == 8 * 52 * 2
    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(0.3, 2.0, (400, 3)) / 60.0, axis=0)  # irregular, 3 streams
    x = np.clip(0.5 + np.cumsum(rng.normal(0, 0.03, (400, 3, 52)), axis=0), -0.2, 1.3)
    x[50, 1] = np.nan  # tracking loss in one stream
    x[90, 0, 7] = np.inf  # a glitch cell
    for i in range(400):
        want = full.step(x[i], t[i])
        assert np.array_equal(fast.step(x[i], t[i]), want, equal_nan=True), i


def test_a_live_network_is_not_taken_for_an_inert_one(tmp_path):
    from faceclean.settings import MODELS

    w = AdaptiveWeights.load(MODELS / "default.npz")
    arrays = dict(w.arrays)
    arrays["head.w"] = arrays["head.w"].copy()
    arrays["head.w"][0, 0] = 0.5  # the core now sets the cut-off
    live = Adaptive(weights=AdaptiveWeights.from_arrays(w.config, arrays))
    assert not live.inert and live.state_bytes == 8 * 52 * (3 + w.hidden)
    boosted = dict(w.arrays, boost=np.full(52, 0.3))  # inert core, a transient gain
    b = Adaptive(weights=AdaptiveWeights.from_arrays(w.config, boosted))
    assert b.inert and b._transient and b.state_bytes == 8 * 52 * 3
    full = _full(Adaptive(weights=AdaptiveWeights.from_arrays(w.config, boosted)))
    rng = np.random.default_rng(5)
    for i in range(120):
        x = rng.uniform(0, 1, 52)
        np.testing.assert_array_equal(b.step(x, i / 60.0), full.step(x, i / 60.0))


def test_the_bench_reference_for_the_default_computes_the_same_function():
    pytest.importorskip("torch")
    from faceclean.neural.reference import AdaptiveReference
    from faceclean.settings import MODELS

    w = AdaptiveWeights.load(MODELS / "default.npz")
    ref, ours = AdaptiveReference(w), Adaptive(weights=w)
    rng = np.random.default_rng(6)
    x = np.clip(0.4 + np.cumsum(rng.normal(0, 0.02, (200, 52)), axis=0), 0, 1)
    ref.start(x[:1])
    ours.step(x[0], 0.0)
    for n in range(1, 200):
        a = ref.step(x[n : n + 1], np.array([1 / 60]))[0]
        np.testing.assert_allclose(a, ours.step(x[n], n / 60), atol=2e-5)  # float32 torch
