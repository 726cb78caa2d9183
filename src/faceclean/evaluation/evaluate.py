"""The RESULTS table: every method x every condition, on sources a model never saw.

Protocol (SPEC section 5, issues 4 and 11):
- Folds: leave one source out (dataset.folds), over every real source. A fold's
  validation takes are every take of its held-out source; its training takes are the
  other sources' takes.
- Artefact models (``ARTEFACTS``): "simulate", faceclean's own simulator (the one the
  learned models train with), and "degrade", a second model written independently of it
  (evaluation/degrade.py) that no training ever uses. Every table reports both.
- Conditions (evaluation/harness.py, the trainers' validation draws the same way): each
  validation take corrupted with a fixed seed at 30, 60 and 120 fps
  (simulate: the "iphone" preset with the rate replaced; degrade: its conditions; the
  artefact draw is the same at every rate) and on "webcam" timing (24-30 fps, irregular
  timestamps, dropped frames, heavier noise). Results are keyed "<artefacts> <condition>".
- Rows: the raw input; the paper's EMA γ 0.3/0.5/0.8 per frame and Gaussian σ 1 and 5
  frames (offline); EMA with a time constant, One Euro and Kalman, each tuned by
  faceclean.filters.tune (global MSE objective) on the fold's training takes corrupted
  the same way at the same condition (first TUNE_SECONDS of each), never on validation
  takes, corrupted by the same artefact model; the learned FC, GBT, LSTM and adaptive
  cleaners, each evaluated per fold with a model whose config["train_sources"] does not
  hold the fold's source (no model: no figure for that fold).
- Do no harm (evaluation/harm.py): every real take as recorded, nothing added, through
  each causal cleaner; the worst shift of a channel's mean level, and blink survival.
- Columns: MSE (the paper's measure), MSE relative to the raw input on the same takes,
  jitter ratio, lag in ms, blink closure (faceclean.evaluation.metrics), each a frame-weighted mean
  over takes, then over folds pooled.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from faceclean.animation import Animation
from faceclean.datasets import dataset
from faceclean.errors import FacecleanError
from faceclean.evaluation import harm, metrics
from faceclean.evaluation.harness import (
    ARTEFACTS,
    CONDITIONS,
    SEED,
    corrupted,
    head,
    run_streams,
)
from faceclean.filters import make
from faceclean.learned import formats
from faceclean.resolve import resolve

TUNE_SECONDS = 20.0  # s of each training take used to tune the classical filters
QUICK_SECONDS = 6.0  # s of each take in --quick mode
METRICS = ("mse", "rel_mse", "jitter_ratio", "lag_ms", "blink_closure")
FORMATS = formats.METHODS

# label -> (method, params, kind); kind: fixed | offline | tuned | learned
FIXED_ROWS: list[tuple[str, str, dict[str, float], str]] = [
    ("EMA γ 0.3", "ema", {"gamma": 0.3}, "fixed"),
    ("EMA γ 0.5", "ema", {"gamma": 0.5}, "fixed"),
    ("EMA γ 0.8", "ema", {"gamma": 0.8}, "fixed"),
    ("Gaussian σ 1 frame", "gaussian", {"sigma_frames": 1.0}, "offline"),
    ("Gaussian σ 5 frames", "gaussian", {"sigma_frames": 5.0}, "offline"),
]
TUNED_ROWS: list[tuple[str, str]] = [
    ("EMA τ (tuned)", "ema"),
    ("One Euro (tuned)", "one-euro"),
    ("Kalman (tuned)", "kalman"),
]
LEARNED_ROWS: list[tuple[str, str]] = [
    ("FC", "fc"), ("GBT", "gbt"), ("LSTM (paper)", "lstm"), ("Adaptive (ours)", "adaptive"),
]  # fmt: skip
SHIPPED = "Adaptive (ours)"  # the row of the shipped default's recipe

Progress = Callable[[str], None]


def model_files(extra: Sequence[str | os.PathLike] = ()) -> list[Path]:
    """Candidate checkpoints: ``extra`` files or folders first, then models/folds/*.npz,
    then the shipped models (default.npz, lstm.npz, fc.npz, gbt.npz)."""
    from faceclean.settings import MODELS

    out: list[Path] = []
    for p in map(Path, extra):
        if not p.exists():
            raise FacecleanError(f"no such model file or folder: {p}")
        out += sorted(p.glob("*.npz")) if p.is_dir() else [p]
    out += sorted((MODELS / "folds").glob("*.npz"))
    shipped = ("default.npz", "lstm.npz", "fc.npz", "gbt.npz")
    out += [MODELS / f for f in shipped if (MODELS / f).is_file()]
    return out


def model_config(path: Path) -> dict[str, Any]:
    """A checkpoint's config JSON (without loading its weights into a cleaner)."""
    from faceclean import strict_json
    from faceclean.learned import formats

    z = formats.read_arrays(path)  # bounded, no pickle
    try:
        raw = str(z["config"][()])
    except (ValueError, KeyError, IndexError) as e:
        raise FacecleanError(f"{path}: not a readable model file ({e})") from None
    config = strict_json.loads(raw, f"{path}: config")
    if not isinstance(config, dict):
        raise FacecleanError(f"{path}: config is not a JSON object")
    return config


def pick_models(files: Sequence[Path], sources: Sequence[str]) -> dict[str, dict[str, Path]]:
    """method -> held-out source -> the first checkpoint that never saw that source.

    Unseen: not among the checkpoint's ``train_sources`` (a model without that record is
    never picked); a source added after a model was trained is unseen by it."""
    picked: dict[str, dict[str, Path]] = {m: {} for _, m in LEARNED_ROWS}
    for f in files:
        config = model_config(f)
        method = FORMATS.get(config.get("format", ""))
        if method is None or "train_sources" not in config:
            continue
        unseen = set(sources) - set(config["train_sources"])
        for s in sorted(unseen):
            picked[method].setdefault(s, f)
    return picked


def _arkit(pairs: Sequence[tuple[Animation, Animation]]) -> list[tuple[Animation, Animation]]:
    """The harness's (noisy, truth) pairs as ARKit-52 takes: (N, 52) values named ARKIT52
    in canonical order, whatever order the take listed them in (Live Link Face writes
    JawRight before JawLeft), so every cleaner sees each channel under its own name."""
    return [
        (Animation.from_arkit(a.times, a.arkit()[0]), Animation.from_arkit(b.times, b.arkit()[0]))
        for a, b in pairs
    ]


def _scores(outs: Sequence[np.ndarray], pairs) -> list[dict[str, float]]:
    return [
        metrics.summary(truth.with_values(o), truth) | {"frames": float(truth.n_frames)}
        for o, (_, truth) in zip(outs, pairs, strict=True)
    ]


def evaluate(
    takes: Sequence[dataset.Take] | None = None,
    *,
    data: str | os.PathLike | None = None,
    models: Sequence[str | os.PathLike] = (),
    seed: int = SEED,
    quick: bool = False,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Run the whole protocol; returns a JSON-ready dict (rendered by faceclean.evaluation.results).

    ``quick``: the first QUICK_SECONDS of each take, one tuning pass on as much.
    """
    from faceclean.filters import tune

    takes = list(takes) if takes is not None else dataset.load_takes(data)
    folds = dataset.folds(takes)
    picked = pick_models(model_files(models), [s for s, _, _ in folds])
    seconds = QUICK_SECONDS if quick else None
    tune_seconds = QUICK_SECONDS if quick else TUNE_SECONDS
    # per-take scores: label -> condition -> list of (source, take, scores)
    per_take: dict[str, dict[str, list]] = {}
    tuned_params: dict[str, dict[str, dict]] = {}

    def record(label, cond, source, val, scores):
        for take, sc in zip(val, scores, strict=True):
            per_take.setdefault(label, {}).setdefault(cond, []).append((source, take.name, sc))

    for source, train, val in folds:
        for artefacts, cond0 in ((a, c) for a in ARTEFACTS for c in CONDITIONS):
            cond = f"{artefacts} {cond0}"
            if progress:
                progress(f"fold {source}, {cond}")
            pairs = _arkit(corrupted(val, cond0, seed, seconds, artefacts))
            inputs = [noisy for noisy, _ in pairs]
            names = inputs[0].names
            record("Raw input", cond, source, val, _scores([a.values for a in inputs], pairs))
            for label, method, params, _ in FIXED_ROWS:
                outs = run_streams(make(method, params, names=names), inputs)
                record(label, cond, source, val, _scores(outs, pairs))
            tune_pairs = _arkit(corrupted(train, cond0, seed + 1, tune_seconds, artefacts))
            for label, method in TUNED_ROWS:
                result = tune.tune(method, tune_pairs)
                tuned_params.setdefault(label, {}).setdefault(cond, {})[source] = result.params
                outs = run_streams(result.build(names), inputs)
                record(label, cond, source, val, _scores(outs, pairs))
            for label, method in LEARNED_ROWS:
                path = picked[method].get(source)
                if path is not None:
                    outs = run_streams(resolve(path).build(names), inputs)
                    record(label, cond, source, val, _scores(outs, pairs))
    if progress:
        progress("do no harm")
    return {
        "seed": seed,
        "quick": quick,
        "artefacts": list(ARTEFACTS),
        "conditions": {
            f"{a} {c}": {"artefacts": a, "condition": c, "preset": p, "fps": f}
            for a in ARTEFACTS
            for c, (p, f) in CONDITIONS.items()
        },
        "harm": _harm(takes, picked, seconds),
        "folds": {
            s: {"val_takes": [t.name for t in v], "train_takes": len(tr)} for s, tr, v in folds
        },
        "models": {m: {s: _shown(p) for s, p in v.items()} for m, v in picked.items()},
        "early_stopped": sorted(
            _shown(p) for v in picked.values() for p in v.values() if "best" in model_config(p)
        ),
        "tuned": tuned_params,
        "rows": _aggregate(per_take),
        "per_take": per_take,
    }


def _shown(path: Path) -> str:
    """A model path as shown in the results: relative to the working folder when inside."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _harm(
    takes: Sequence[dataset.Take], picked: dict[str, dict[str, Path]], seconds: float | None
) -> dict[str, dict[str, Any]]:
    """The do-no-harm table: shipped presets and defaults on every take; fold models on
    the source they never saw."""
    if seconds is not None:
        takes = [dataclasses.replace(t, animation=head(t.animation, seconds)) for t in takes]
    from faceclean.settings import MODELS

    rows: dict[str, Any] = {
        f"{label} (shipped preset)": (lambda _t, m=method: resolve(m).build())
        for label, method in TUNED_ROWS
    }
    for label, method in LEARNED_ROWS:
        if method in ("fc", "gbt"):
            continue
        rows[label] = lambda t, m=method: (
            resolve(picked[m][t.source]).build() if t.source in picked[m] else None
        )
    default = MODELS / "default.npz"
    if default.is_file():
        from faceclean.cleaner import Cleaner as Facade

        rows["Shipped default"] = lambda _t: Facade.load(default)
    return harm.table(rows, takes)


def weighted_mean(scores: list[dict[str, float]], key: str) -> float:
    """Frame-weighted mean of one measure over takes, ignoring NaN figures."""
    v = np.array([s[key] for s in scores])
    w = np.array([s["frames"] for s in scores])
    ok = np.isfinite(v)
    return float(np.average(v[ok], weights=w[ok])) if ok.any() else float("nan")


def _aggregate(per_take: dict[str, dict[str, list]]) -> dict[str, dict[str, dict]]:
    """label -> condition -> {"all": figures, "<source>": figures} with rel_mse vs raw."""
    rows: dict[str, dict[str, dict]] = {}
    raw = per_take["Raw input"]
    for label, by_cond in per_take.items():
        for cond, items in by_cond.items():
            groups = {"all": items} | {s: [i for i in items if i[0] == s] for s, _, _ in items}
            out = {}
            for g, its in groups.items():
                keys = {(s, n) for s, n, _ in its}
                base = [sc for s, n, sc in raw[cond] if (s, n) in keys]
                figs = {
                    k: weighted_mean([sc for _, _, sc in its], k) for k in METRICS if k != "rel_mse"
                }
                figs["rel_mse"] = figs["mse"] / weighted_mean(base, "mse")
                figs["takes"] = len(its)
                out[g] = figs
            rows.setdefault(label, {})[cond] = out
    return rows


def dumps(results: dict[str, Any]) -> str:
    """The results as strict JSON (NaN and inf figures become null)."""

    def clean(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, list | tuple):
            return [clean(x) for x in v]
        if isinstance(v, float) and not np.isfinite(v):
            return None
        return v

    return json.dumps(clean(results), indent=1, allow_nan=False) + "\n"
