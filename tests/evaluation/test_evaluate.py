"""The evaluation harness on a tiny two-source data folder: every row and column, raw's
relative MSE of 1, learned rows only on the source their model never saw, and the CLI."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from faceclean import io
from faceclean.cli import main
from faceclean.datasets import performer
from faceclean.evaluation import evaluate
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
    keys = {f"{a} {c}" for a in evaluate.ARTEFACTS for c in evaluate.CONDITIONS}
    assert set(results["conditions"]) == keys
    for label in labels:
        assert set(rows[label]) == keys
        for cond in keys:
            fig = rows[label][cond]["all"]
            assert set(evaluate.METRICS) <= set(fig)
            assert np.isfinite(fig["mse"]) and fig["mse"] >= 0
    for cond in keys:
        for source in ("all", "one", "two"):
            assert rows["Raw input"][cond][source]["rel_mse"] == pytest.approx(1.0)
        assert rows["Raw input"][cond]["all"]["jitter_ratio"] > 1.0  # raw input jitters
        smooth = rows["Gaussian σ 5 frames"][cond]["all"]["jitter_ratio"]
        assert smooth < rows["Raw input"][cond]["all"]["jitter_ratio"]


def test_learned_rows_only_on_unseen_sources(results, fc_model):
    # extra models come first; any other pick never trained on its source
    assert results["models"]["fc"]["two"] == str(fc_model)
    for method, per in results["models"].items():
        for source, path in per.items():
            assert source not in evaluate.model_config(Path(path))["train_sources"], method
    fc = results["rows"]["FC"]["degrade 60 fps"]
    assert "two" in fc
    assert fc["all"]["takes"] == len(results["models"]["fc"])


def test_tuned_filters_are_tuned_per_fold(results):
    tuned = results["tuned"]["One Euro (tuned)"]["degrade 60 fps"]
    assert set(tuned) == {"one", "two"}
    assert all(p["min_cutoff"] > 0 for p in tuned.values())


def test_markdown_has_every_table(results):
    text = report.markdown(results)
    for cond in results["conditions"]:
        assert f"## {cond}" in text
    assert "| Raw input | " in text and "| One Euro (tuned) | " in text
    assert "## Targets" in text and "MSE × raw per held-out source (degrade)" in text
    assert "## Do no harm" in text and "| One Euro (tuned) (shipped preset) |" in text
    assert "## Never ship worse" in text and "**Verdict: " in text


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
    # a source added after a model was trained is one it never saw
    assert evaluate.pick_models([fc_model], ["one", "two", "three"])["fc"] == {
        "two": fc_model,
        "three": fc_model,
    }


def test_targets_compare_with_the_tuned_one_euro_on_the_same_takes(results):
    checks = dict(report.targets(results, "FC"))
    assert len(checks) == 6 and set(checks["lag ≤ 8 ms"]) == set(results["conditions"])
    rows, per = results["rows"], results["per_take"]
    cond = "degrade 60 fps"
    fc = rows["FC"][cond]["all"]["mse"]
    takes = {(s, n) for s, n, _ in per["FC"][cond]}  # only those FC has figures for
    oe = evaluate.weighted_mean(
        [sc for s, n, sc in per["One Euro (tuned)"][cond] if (s, n) in takes], "mse"
    )
    cell = checks["MSE ≤ 0.85× tuned One Euro"][cond]
    assert cell.split()[0] == report._fmt(fc / oe)
    assert ("missed" in cell) == (fc / oe > 0.85) and cell.endswith(("met", "**missed**"))


def test_do_no_harm_table_on_clean_takes(results):
    harm = results["harm"]
    oe = harm["One Euro (tuned) (shipped preset)"]
    assert oe["takes"] == 2 and 0.0 <= oe["max_shift"] < 0.01
    assert {"max_shift", "where", "blink_mean", "blink_min", "passes"} <= set(oe)


def test_the_second_artefact_model_drives_the_verdict(results):
    ok, lines = report.verdict(results, "FC")
    assert len([x for x in lines if x.startswith("| degrade")]) == 4
    assert not any(x.startswith("| simulate") for x in lines)
    assert ok == all("**no**" not in x for x in lines)
    assert report.targets(results, "LSTM") == []  # no LSTM model here


def test_the_trainers_validation_draws_the_results_streams(data, results):
    """One harness: for the same (condition, take, seed), the stream the trainers validate
    on (harness.streams) is the one RESULTS scores: fold "one"'s raw-input figures."""
    from faceclean.datasets import dataset
    from faceclean.evaluation import degrade, harness, metrics

    assert tuple(harness.CONDITIONS) == degrade.CONDITIONS  # one naming for both models
    val = [
        dataclasses.replace(t, animation=harness.head(t.animation, evaluate.QUICK_SECONDS))
        for t in dataset.load_takes(data)
        if t.source == "one"
    ]
    for s in harness.streams(val, list(harness.CONDITIONS), seed=5):
        noisy, truth = (a.with_values(a.arkit()[0]) for a in (s.noisy, s.truth))
        want = metrics.summary(noisy, truth) | {"frames": float(truth.n_frames)}
        rows = results["per_take"]["Raw input"][f"simulate {s.condition}"]
        [got] = [sc for source, _, sc in rows if source == "one"]
        np.testing.assert_equal(got, want)
