"""The evaluation harness on a tiny two-source data folder: every row and column, raw's
relative MSE of 1, learned rows only on the source their model never saw, and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean import io
from faceclean.cli import main
from faceclean.evaluation import evaluate, performer
from faceclean.evaluation import results as report


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("takes")
    for i, source in enumerate(("one", "two")):
        (root / source).mkdir()
        io.save(performer.perform(3.0, seed=i, fps=60.0), root / source / f"take{i}.csv")
    return root


@pytest.fixture(scope="module")
def fc_model(tmp_path_factory):
    """An FC checkpoint (random weights) that held out source "two"."""
    torch = pytest.importorskip("torch")
    from faceclean.neural import baselines

    torch.manual_seed(0)
    net = baselines.FCNet(52, hidden=(8,)).eval()
    path = tmp_path_factory.mktemp("models") / "fc-two.npz"
    baselines.save_fc(net, path, {"val_sources": ["two"], "train_sources": ["one"]})
    return path


@pytest.fixture(scope="module")
def results(data, fc_model):
    return evaluate.evaluate(data=data, models=[fc_model], quick=True, seed=5)


def test_every_row_and_condition_with_all_columns(results):
    rows = results["rows"]
    labels = ["Raw input", *(r[0] for r in evaluate.FIXED_ROWS)]
    labels += [r[0] for r in evaluate.TUNED_ROWS] + ["FC"]
    assert set(labels) <= set(rows)
    for label in labels:
        assert set(rows[label]) == set(evaluate.CONDITIONS)
        for cond in evaluate.CONDITIONS:
            fig = rows[label][cond]["all"]
            assert set(evaluate.METRICS) <= set(fig)
            assert np.isfinite(fig["mse"]) and fig["mse"] >= 0
    for cond in evaluate.CONDITIONS:
        for source in ("all", "one", "two"):
            assert rows["Raw input"][cond][source]["rel_mse"] == pytest.approx(1.0)
        assert rows["Raw input"][cond]["all"]["jitter_ratio"] > 1.0  # raw input jitters
        smooth = rows["Gaussian σ 5 frames"][cond]["all"]["jitter_ratio"]
        assert smooth < rows["Raw input"][cond]["all"]["jitter_ratio"]


def test_learned_rows_only_on_unseen_sources(results, fc_model):
    assert results["models"]["fc"] == {"two": str(fc_model)}
    fc = results["rows"]["FC"]["60 fps"]
    assert "two" in fc and "one" not in fc
    assert fc["all"]["takes"] == 1


def test_tuned_filters_are_tuned_per_fold(results):
    tuned = results["tuned"]["One Euro (tuned)"]["60 fps"]
    assert set(tuned) == {"one", "two"}
    assert all(p["min_cutoff"] > 0 for p in tuned.values())


def test_markdown_has_every_table(results):
    text = report.markdown(results)
    for cond in evaluate.CONDITIONS:
        assert f"## {cond}" in text
    assert "| Raw input | " in text and "| One Euro (tuned) | " in text
    assert "## Targets" in text and "MSE × raw per held-out source" in text


def test_cli_quick_writes_markdown_and_json(data, tmp_path, capsys):
    md, js = tmp_path / "RESULTS.md", tmp_path / "results.json"
    argv = ["eval", "--data", str(data), "--quick", "--markdown", str(md), "--json", str(js)]
    assert main([*argv, "--models", str(tmp_path / "none")]) == 2  # bad input: exit 2
    assert "faceclean: no such model" in capsys.readouterr().err
    assert main(argv) == 0
    assert md.read_text().startswith("# Results")
    assert "Raw input" in json.loads(js.read_text())["rows"]
    assert "NaN" not in js.read_text() and "Infinity" not in js.read_text()  # strict JSON
    assert "| method | MSE |" in capsys.readouterr().out


def test_a_model_that_trained_on_a_source_is_not_evaluated_on_it(tmp_path, fc_model):
    torch = pytest.importorskip("torch")
    from faceclean.neural import baselines

    torch.manual_seed(1)
    seen = tmp_path / "take-split.npz"  # a take-level split: every source in both lists
    facts = {"val_sources": ["one", "two"], "train_sources": ["one", "two"]}
    baselines.save_fc(baselines.FCNet(52, hidden=(4,)), seen, facts)
    picked = evaluate.pick_models([seen, fc_model], ["one", "two"])
    assert picked["fc"] == {"two": fc_model} and picked["gbt"] == {} and picked["lstm"] == {}


def test_targets_compare_with_the_best_filter_on_the_same_takes(results):
    checks = dict(report.targets(results, "FC"))
    assert len(checks) == 5 and set(checks["lag < 10 ms"]) == set(evaluate.CONDITIONS)
    rows = results["rows"]
    fc = rows["FC"]["60 fps"]["all"]["mse"]
    best = min(rows[f]["60 fps"]["two"]["mse"] for f in report.CAUSAL_FILTERS)  # FC: "two" only
    cell = checks["MSE ≤ 0.8× best tuned causal filter"]["60 fps"]
    assert cell.split()[0] == report._fmt(fc / best)
    assert ("missed" in cell) == (fc / best > 0.8) and cell.endswith(("met", "**missed**"))
    assert report.targets(results, "LSTM") == []  # no LSTM model here
