"""The paper's LSTM on pairs (neural/pair_lstm.py): a long run stops and continues where it
stood, and stops itself once validation has not improved for ``patience`` epochs."""

from __future__ import annotations

import numpy as np

from faceclean.animation import Animation
from faceclean.datasets import paired
from faceclean.datasets.performer import perform
from faceclean.neural import checkpoint
from faceclean.neural.pair_lstm import train_lstm
from faceclean.neural.train import last_path

NAMES = ("eyeBlinkLeft", "jawOpen", "mouthSmileLeft")


def _pairs(n: int, seed: int) -> list[paired.Pair]:
    out = []
    for k in range(n):
        truth = perform(4.0, seed + k, fps=30.0)
        y = np.stack([truth.channel(c) for c in NAMES], axis=1)
        x = np.clip(0.7 * y + np.random.default_rng(k).normal(0, 0.02, y.shape), 0, 1)
        out.append(paired.Pair(f"p{k}", Animation(truth.times, x, NAMES),
                               Animation(truth.times, y, NAMES), "g", "studio"))  # fmt: skip
    return out


def _epochs(events) -> list[int]:
    return [e["epoch"] for e in events if e["event"] == "epoch"]


def test_a_stopped_run_continues_from_its_last_epoch(tmp_path):
    train, val = _pairs(2, 0), _pairs(1, 9)
    out = tmp_path / "m.npz"
    first: list[dict] = []
    train_lstm(train, val, out, epochs=2, hidden=8, layers=1, report=first.append)
    state = checkpoint.read(last_path(out))[0]["train_state"]
    assert _epochs(first) == [0, 1] and state["epoch"] == 1
    more: list[dict] = []
    best = train_lstm(train, val, out, epochs=4, hidden=8, layers=1, report=more.append,
                      resume=True)  # fmt: skip
    assert more[0]["event"] == "resume" and _epochs(more) == [2, 3]  # not from 0 again
    assert checkpoint.read(last_path(out))[0]["train_state"]["epoch"] == 3
    scores = [e["val_mse"] for e in first + more if e["event"] == "epoch"]
    assert best["val_mse"] == min(scores)  # the best of all four epochs, across the stop
    again: list[dict] = []
    train_lstm(train, val, out, epochs=4, hidden=8, layers=1, report=again.append, resume=True)
    assert _epochs(again) == []  # finished: nothing redone


def test_patience_stops_a_run_that_no_longer_improves(tmp_path):
    train, val = _pairs(2, 0), _pairs(1, 9)
    events: list[dict] = []
    best = train_lstm(train, val, tmp_path / "m.npz", epochs=30, hidden=8, layers=1,
                      patience=2, lr=0.3, report=events.append)  # fmt: skip
    epochs = _epochs(events)
    assert len(epochs) < 30  # a step this large stops improving long before 30 epochs
    assert epochs[-1] - best["epoch"] == 2  # exactly ``patience`` epochs after the best


def test_train_pairs_lstm_resumes_from_its_last_file(tmp_path, capsys):
    from faceclean import io
    from faceclean.cli import main

    folder = tmp_path / "pairs"
    folder.mkdir()
    for p in _pairs(3, 0):
        io.save(p.tracked, folder / f"{p.name}.raw.csv")
        io.save(p.truth, folder / f"{p.name}.clean.csv")
    model = tmp_path / "m.npz"
    cli = ["train", "--pairs", str(folder), "--arch", "lstm", "--out", str(model)]
    assert main([*cli, "--epochs", "1"]) == 0
    err = capsys.readouterr().err
    assert "epoch 0:" in err and last_path(model).is_file()
    assert main([*cli, "--epochs", "2", "--resume", str(last_path(model))]) == 0
    err = capsys.readouterr().err
    assert "epoch 1:" in err and "epoch 0:" not in err  # continued, not redone
    assert main([*cli, "--resume", str(model)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.strip().endswith(f"--resume {last_path(model)}")
