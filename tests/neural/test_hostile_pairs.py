"""Issue 37, training pairs: ``train --pairs`` trains on real pairs only, and no model it
writes holds a number its loader would refuse.

Black box as the red teams are (``faceclean`` in a child process, one line and exit 2 for
a refusal, no file left), plus the pieces: ``paired.usable`` and ``formats.write``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_redteam import ARKIT, fc, no_temp_files, ok, plain_text, refused

from faceclean.datasets import paired
from faceclean.errors import FacecleanError
from faceclean.learned.tracker_map import MapWeights
from faceclean.neural import tracker_map as fit

MP = [c for c in ARKIT if c != "tongueOut"]  # MediaPipe's 51 channels
N = 90  # frames of a pair (3 s at 30 fps)


def _truth(rng) -> np.ndarray:
    t = np.arange(N)[:, None] / 30.0
    return np.clip(0.4 + 0.3 * np.sin(t * rng.uniform(1, 4, len(ARKIT))), 0, 1)  # (N, 52)


def write_pairs(folder: Path, kind: str = "good", groups=("a", "b", "c")) -> Path:
    """Two pairs per group as ``faceclean pairs`` writes them, the tracked takes spoiled
    as ``kind`` says."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    t = np.arange(N) / 30.0
    for g in groups:
        for i in range(2):
            y = _truth(rng)
            x = 0.8 * y[:, [ARKIT.index(c) for c in MP]] + 0.05 + rng.normal(0, 0.02, (N, 51))
            if kind == "inf":
                x[:] = np.inf
            elif kind == "half-inf":
                x[: N // 2] = -np.inf
            elif kind == "1e308":
                x[::3, :5] = 1e308
            names = MP
            if kind == "truth-as-tracked":
                x, names = y.copy(), ARKIT
            name = f"{g}-s{i}"
            (folder / f"{name}.tracked.csv").write_bytes(plain_text(N, names, x, t))
            (folder / f"{name}.truth.csv").write_bytes(plain_text(N, ARKIT, y, t))
            job = {"source": "synth:1", "group": g, "setting": "studio", "seed": i}
            (folder / f"{name}.json").write_text(json.dumps({"format": "faceclean-pair/1",
                                                             "job": job}))  # fmt: skip
    return folder


def train(tmp_path: Path, folder: Path, *extra):
    model = tmp_path / "m.npz"
    r = fc("train", "--pairs", folder, "--out", model, *extra, timeout=120.0)
    return r, model


# -- poisoned values: read as missing, the model finite and loadable ---------------------------


@pytest.mark.parametrize("kind", ["half-inf", "1e308"])
def test_poisoned_tracked_values_never_reach_the_model(tmp_path, kind):
    folder = write_pairs(tmp_path / "p", kind)
    r, model = train(tmp_path, folder, "--arch", "ridge")
    assert r is not None and r.returncode == 0, r.stderr[-600:]
    assert "read as missing" in r.stderr and "Traceback" not in r.stderr
    w = MapWeights.load(model)  # the loader's own checks
    assert all(np.isfinite(a).all() for a in w.arrays.values())
    out = tmp_path / "o.csv"
    ok(fc("clean", folder / "a-s0.tracked.csv", "-o", out, "--model", model))
    from faceclean import io

    assert np.isfinite(io.load(out).values[N // 2 :]).all()


@pytest.mark.parametrize("kind", ["half-inf", "1e308"])
def test_the_default_map_fits_finite_weights_on_poisoned_pairs(tmp_path, kind):
    """The map's own fit (one candidate: the search is the same code) on what
    ``train --pairs`` hands it."""
    loaded = paired.load(write_pairs(tmp_path / "p", kind))
    kept, skipped, notes = paired.usable(loaded)
    assert len(kept) == len(loaded) and not skipped and len(notes) >= 1
    w = fit.fit(kept[:4], kept[4:], prefilters=[(4.0, 1.0, 1.0)], lams=(0.1,), cv=False)
    assert all(np.isfinite(a).all() for a in w.arrays.values())
    w.save(tmp_path / "m.npz")
    MapWeights.load(tmp_path / "m.npz")


def test_pairs_with_nothing_but_infinite_readings_write_nothing(tmp_path):
    r, model = train(tmp_path, write_pairs(tmp_path / "p", "inf"), "--arch", "ridge")
    refused(r)
    assert "no pairs found in" in r.stderr and "a-s0" in r.stderr
    assert not model.exists()
    no_temp_files(tmp_path)


# -- what is no pair ----------------------------------------------------------------------------


def _json_files(folder: Path) -> None:
    folder.mkdir()
    for i in range(3):
        (folder / f"take{i}.json").write_text(json.dumps({"format": "faceclean-pair/1"}))


def _truth_takes(folder: Path) -> None:
    folder.mkdir()
    for i in range(3):
        (folder / f"s{i}.truth.csv").write_bytes(plain_text(N))


@pytest.mark.parametrize(
    "kind", ["json-files", "truth-takes", "truth-as-tracked", "empty-subfolders"]
)
def test_a_folder_without_real_pairs_is_refused_in_one_line(tmp_path, kind):
    folder = tmp_path / "p"
    if kind == "json-files":
        _json_files(folder)
    elif kind == "truth-takes":
        _truth_takes(folder)
    elif kind == "truth-as-tracked":
        write_pairs(folder, "truth-as-tracked")
    else:
        (folder / "a" / "b").mkdir(parents=True)
    r, model = train(tmp_path, folder)
    refused(r)
    assert f"no pairs found in {folder}: " in r.stderr, r.stderr
    if kind == "truth-as-tracked":
        assert "is its truth" in r.stderr
    assert not model.exists()
    no_temp_files(tmp_path)


def test_a_pair_that_is_no_pair_is_skipped_and_said(tmp_path):
    """Among real pairs, one whose tracked take is its truth: skipped, said, not trained on."""
    folder = write_pairs(tmp_path / "p")
    write_pairs(tmp_path / "q", "truth-as-tracked", groups=("z",))
    for f in (tmp_path / "q").iterdir():
        f.rename(folder / f.name)
    kept, skipped, _ = paired.usable(paired.load(folder))
    assert sorted(p.name for p in kept) == [f"{g}-s{i}" for g in "abc" for i in range(2)]
    assert [s.split(":")[0] for s in skipped] == ["z-s0", "z-s1"]


def test_a_long_header_cell_names_the_pair_file(tmp_path):
    folder = write_pairs(tmp_path / "p", groups=("a",))
    sub = folder / "session2"
    sub.mkdir()
    bad = sub / "x.tracked.csv"
    head, _, rest = (folder / "a-s0.tracked.csv").read_bytes().partition(b"\n")
    bad.write_bytes(head + b"," + b"n" * 300 + b"\n" + rest.replace(b"\n", b",0.5\n"))
    (sub / "x.truth.csv").write_bytes((folder / "a-s0.truth.csv").read_bytes())
    r, model = train(tmp_path, folder)
    refused(r)
    assert "session2/x.tracked.csv" in r.stderr and "256" in r.stderr, r.stderr
    assert not model.exists()


# -- a model is checked before it is written ----------------------------------------------------


def _map() -> MapWeights:
    return fit.blank(["jawOpen", "eyeBlinkLeft"], 0, (4.0, 1.0, 1.0), rest=True)


@pytest.mark.parametrize(
    ("key", "value", "said"),
    [
        ("a", np.nan, "holds 1 NaN or infinite"),
        ("c", np.inf, "holds 1 NaN or infinite"),
        ("lift_knee", 7.0, "lift_knee must be within"),
        ("sd", -1.0, "must be > 0"),
    ],
)
def test_a_model_its_loader_refuses_is_never_written(tmp_path, key, value, said):
    w = _map()
    w.arrays[key] = w.arrays[key].copy()
    w.arrays[key].flat[0] = value
    path = tmp_path / "m.npz"
    with pytest.raises(FacecleanError, match=said) as e:
        w.save(path)
    assert str(e.value).startswith("m.npz: not written: ")
    assert list(tmp_path.iterdir()) == []


def test_non_finite_facts_are_written_as_null_and_the_model_loads(tmp_path):
    w = _map()
    w.config.update(val_jitter=float("nan"), val_lag_ms=float("inf"))
    w.save(tmp_path / "m.npz")
    back = MapWeights.load(tmp_path / "m.npz")
    assert back.config["val_jitter"] is None and back.config["val_lag_ms"] is None


def test_an_lstm_with_a_nan_weight_is_never_written(tmp_path):
    import torch

    from faceclean.neural import checkpoint
    from faceclean.neural.model import LSTMCleaner

    model = LSTMCleaner(channels=["jawOpen", "eyeBlinkLeft"], K=1, hidden=4, layers=1)
    with torch.no_grad():
        model.lstm[0].weight_hh.view(-1)[3] = float("nan")  # one the loader never looked at
    with pytest.raises(FacecleanError, match="lstm.0.w_hh"):
        checkpoint.save(model, tmp_path / "m.npz")
    assert list(tmp_path.iterdir()) == []


def test_train_says_the_model_it_replaces_and_refuses_a_seed_out_of_range(tmp_path):
    folder = write_pairs(tmp_path / "p")
    out = tmp_path / "m.npz"
    out.write_text("keep")  # not even a model: written over, and said
    r, _ = train(tmp_path, folder, "--arch", "ridge")
    assert r is not None and r.returncode == 0, r.stderr[-600:]
    assert f"\nreplaced {out}: ridge" in r.stdout, r.stdout
    for seed in ("-1", str(2**63)):
        r, _ = train(tmp_path, folder, "--arch", "ridge", "--seed", seed)
        refused(r)
        assert "--seed must be an integer in [0, 2**63)" in r.stderr


def test_a_broken_resume_file_is_said_without_a_word_about_the_pairs(tmp_path):
    pytest.importorskip("torch")
    folder = write_pairs(tmp_path / "p")
    last = tmp_path / "m.last.npz"
    last.write_text("garbage")
    r, _ = train(tmp_path, folder, "--arch", "lstm", "--epochs", "1", "--hidden", "4",
                 "--resume", str(last))  # fmt: skip
    refused(r)
    assert "m.last.npz: not a model .npz" in r.stderr and "no pair holds" not in r.stderr


@pytest.mark.parametrize("flag, value", [("--epochs", "-1"), ("--patience", "-1"),
                                         ("--hidden", "0"), ("--lr", "nan"), ("--K", "-1"),
                                         ("--layers", "0"), ("--batch", "0"),
                                         ("--w-acc", "nan")])  # fmt: skip
def test_a_training_number_that_means_nothing_is_refused_before_any_work(tmp_path, flag, value):
    # --epochs -1 ran no epoch and said "wrote" a model it never wrote
    r, model = train(tmp_path, write_pairs(tmp_path / "p"), "--arch", "lstm", flag, value)
    refused(r)
    assert flag in r.stderr and not model.exists()


def test_eval_of_pairs_of_one_source_says_there_is_no_fold(tmp_path):
    # one source leaves no fold: max() of nothing ended on an internal error
    r = fc("eval", "--pairs", write_pairs(tmp_path / "p", groups=("a",)), timeout=120.0)
    refused(r)
    assert "no fold to score" in r.stderr and "two sources or more" in r.stderr


@pytest.mark.parametrize("arch", ["adaptive", "lstm"])
def test_takes_that_leave_nothing_to_validate_on_are_refused_and_no_model_written(tmp_path, arch):
    # one take of one source: early stopping kept the starting model, wrote it, exit 0
    # (fc and gbt train a fixed budget with no validation, as SPEC section 3 has them)
    pytest.importorskip("torch")
    t = np.arange(90) / 30.0
    v = 0.3 + 0.2 * np.sin(np.outer(t, np.arange(1, 5)))
    (tmp_path / "data" / "me").mkdir(parents=True)
    from faceclean import io
    from faceclean.animation import Animation

    io.save(Animation(t, v, ("jawOpen", "eyeBlinkLeft", "mouthSmileLeft", "browInnerUp")),
            tmp_path / "data" / "me" / "take.csv")  # fmt: skip
    out = tmp_path / "m.npz"
    r = fc("train", "--data", tmp_path / "data", "--arch", arch, "--epochs", "1", "--out", out,
           timeout=120.0)  # fmt: skip
    refused(r)
    assert "no take left to validate on" in r.stderr and not out.exists()


@pytest.mark.parametrize(
    "flag, value",
    [("--mesh", "x.npz"), ("--report", "default"), ("--data", "."), ("--synthetic-minutes", "2")],
)
def test_an_option_of_take_training_beside_pairs_is_refused_not_ignored(tmp_path, flag, value):
    r, model = train(tmp_path, write_pairs(tmp_path / "p"), flag, value)
    refused(r)
    assert f"{flag} trains on takes, not with --pairs" in r.stderr and not model.exists()
