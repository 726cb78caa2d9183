"""The dataset pipeline: loading, splits by take and source, augmentation, chunks."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import INDEX
from faceclean.datasets import dataset, performer
from faceclean.datasets.dataset import Augmentation, Take
from faceclean.errors import FacecleanError
from faceclean.settings import takes_dir


@pytest.fixture(scope="module")
def takes() -> list[Take]:
    return [
        Take(src, f"{src}{i}", performer.perform(8.0, seed=10 * k + i))
        for k, src in enumerate(("a", "b", "c"))
        for i in range(3)
    ]


def test_load_takes_names_sources_by_subfolder(tmp_path):
    for src, name in (("alice", "one"), ("alice", "two"), ("bob", "three")):
        (tmp_path / src).mkdir(exist_ok=True)
        io.save(performer.perform(1.0, seed=len(name)), tmp_path / src / f"{name}.csv")
    got = dataset.load_takes(tmp_path)
    assert [(t.source, t.name) for t in got] == [
        ("alice", "one"),
        ("alice", "two"),
        ("bob", "three"),
    ]
    assert got[0].animation.n_frames == 61
    with pytest.raises(FacecleanError):
        dataset.load_takes(tmp_path / "none")


@pytest.mark.skipif(takes_dir() is None, reason="shared data folder absent")
def test_real_takes_load_with_their_tracking_loss():
    got = {t.name: t for t in dataset.load_takes()}
    # a take or a source added to the shared folder must not break this
    assert {"alexdjulin", "jmtechart", "neurosync"} <= {t.source for t in got.values()}
    assert (~got["apfel"].animation.valid).sum() == 35
    val = dataset.validation_chunks([got["apfel"]])
    lost = ~val.observed
    assert lost.any() and not val.valid[lost].any() and np.isfinite(val.truth).all()


def test_split_never_shares_a_take(takes):
    train, val = dataset.split(takes, val_sources=["b"], val_fraction=0.34, seed=1)
    names = lambda ts: {t.name for t in ts}  # noqa: E731
    assert not names(train) & names(val)
    assert names(train) | names(val) == names(takes)
    assert {"b0", "b1", "b2"} <= names(val)
    for src in ("a", "c"):  # one of each other source's three takes
        assert sum(t.source == src for t in val) == 1
    assert dataset.split(takes, val_fraction=0.34, seed=1) == dataset.split(
        takes, val_fraction=0.34, seed=1
    )
    with pytest.raises(FacecleanError):
        dataset.split(takes, val_sources=["zzz"])


def test_leave_one_source_out_folds(takes):
    folds = dataset.folds(takes)
    assert [f[0] for f in folds] == ["a", "b", "c"]
    for source, train, val in folds:
        assert {t.source for t in val} == {source}
        assert source not in {t.source for t in train} and len(train) + len(val) == len(takes)


def test_chunks_have_the_paper_shape_and_overlap():
    t = np.arange(1000) / 60.0
    x = np.random.default_rng(0).random((1000, 52))
    anim = Animation.from_arkit(t, x)
    c = dataset.take_chunks(anim, anim)
    starts = [0, 50, 100] + list(range(150, 801, 50))
    assert c.noisy.shape == (len(starts), 200, 52) and c.noisy.dtype == np.float32
    assert c.times.shape == (len(starts), 200) and c.times.dtype == np.float64
    assert np.array_equal(c.noisy[1, :150], c.noisy[0, 50:])  # overlap 150
    assert np.array_equal(c.noisy[-1, -1], x[-1].astype(np.float32))  # tail covered
    assert np.all(c.times[:, 0] == 0) and np.allclose(np.diff(c.times, axis=1), 1 / 60)
    short = dataset.take_chunks(*(Animation.from_arkit(t[:120], x[:120]),) * 2)
    assert short.noisy.shape == (1, 200, 52) and short.valid.sum() == 120
    assert np.all(np.diff(short.times[0]) > 0)


def test_missing_frames_are_never_truth():
    t = np.arange(600) / 60.0
    x = np.full((600, 52), 0.4)
    x[200:260] = np.nan  # the source lost tracking here
    c = dataset.make_chunks([Take("s", "gap", Animation.from_arkit(t, x))], seed=3, preset="webcam")
    assert np.isfinite(c.noisy).all() and np.isfinite(c.truth).all()
    assert not (c.valid & ~c.observed).any()
    # every valid frame's truth is the source's (augmented) constant, never a filled value
    assert np.ptp(c.truth[c.valid], axis=0).max() < 1e-6
    plain = dataset.make_chunks(
        [Take("s", "gap", Animation.from_arkit(t, x))], 3, augmentation=None
    )
    assert np.allclose(plain.truth[plain.valid], 0.4) and (~plain.valid).sum() > 0
    assert (~c.valid).sum() > 0


def test_epochs_are_fresh_and_seeded_validation_is_fixed(takes):
    e0, e1 = dataset.epochs(takes, seed=0, count=2)
    again = dataset.epoch_chunks(takes, 0, 0)
    assert np.array_equal(e0.noisy, again.noisy) and np.array_equal(e0.times, again.times)
    assert e0.noisy.shape[1:] == (200, 52)
    assert e0.noisy.shape != e1.noisy.shape or not np.array_equal(e0.noisy, e1.noisy)
    v1, v2 = dataset.validation_chunks(takes), dataset.validation_chunks(takes)
    assert np.array_equal(v1.noisy, v2.noisy) and np.array_equal(v1.truth, v2.truth)


def test_training_rates_span_24_to_120_fps(takes):
    rates = []
    for epoch in range(6):
        c = dataset.epoch_chunks(takes, 5, epoch)
        rates += list(1.0 / np.median(np.diff(c.times, axis=1), axis=1))
    assert min(rates) < 40 and max(rates) > 80
    assert min(rates) > 22 and max(rates) < 130


def test_synthetic_minutes_add_performer_takes(takes):
    base = dataset.epoch_chunks(takes[:1], 0, 0)
    more = dataset.epoch_chunks(takes[:1], 0, 0, synthetic_minutes=0.5)
    assert len(more) > len(base)
    assert [t.source for t in dataset.synthetic_takes(1.5, seed=0)] == ["synthetic"] * 2


def test_mirror_swaps_sides_and_gaze_direction():
    t = np.arange(100) / 60.0
    x = np.zeros((100, 52))
    x[:, INDEX["eyeLookOutLeft"]] = x[:, INDEX["eyeLookInRight"]] = 0.5  # looking left
    x[:, INDEX["mouthSmileLeft"]], x[:, INDEX["jawOpen"]] = 0.7, 0.2
    still = Augmentation(gain=0, offset=0, speed=0, warp=0, mirror=1.0)
    m = dataset.augment(Animation.from_arkit(t, x), np.random.default_rng(0), still)
    assert np.array_equal(m.times, t)
    assert np.all(m.channel("eyeLookOutRight") == 0.5) and np.all(m.channel("eyeLookInLeft") == 0.5)
    assert np.all(m.channel("eyeLookOutLeft") == 0) and np.all(m.channel("mouthSmileRight") == 0.7)
    assert np.all(m.channel("jawOpen") == 0.2)


def test_augmentation_keeps_range_and_time_order(takes):
    anim = takes[0].animation
    for seed in range(5):
        a = dataset.augment(anim, np.random.default_rng(seed), Augmentation())
        assert a.values.min() >= 0 and a.values.max() <= 1.0
        assert np.all(np.diff(a.times) > 0)
        assert 0.7 < a.duration / anim.duration < 1.5


def test_torch_views_shard_batches_evenly(takes):
    pytest.importorskip("torch")
    from faceclean.neural.data import ChunkDataset, EpochStream

    per_rank = [list(EpochStream(takes, 0, 4, rank=r, world_size=2)) for r in range(2)]
    assert len(per_rank[0]) == len(per_rank[1]) > 0
    batch = per_rank[0][0]
    assert (
        tuple(batch["noisy"].shape) == (4, 200, 52)
        and batch["valid"].dtype.is_floating_point is False
    )
    val = ChunkDataset(dataset.validation_chunks(takes))
    assert tuple(val[0]["truth"].shape) == (200, 52) and len(val) > 0
