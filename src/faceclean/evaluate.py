"""The RESULTS table: every method x every condition, on sources a model never saw.

Protocol (SPEC section 5, issue 4):
- Folds: leave one source out (dataset.folds). A fold's validation takes are every take
  of its held-out source; its training takes are the other sources' takes.
- Conditions: each validation take corrupted by the simulator with a fixed seed, at 30,
  60 and 120 fps (the "iphone" preset with the rate replaced; the artefact parameters are
  the same draw at every rate) and on "webcam" timing (that preset: 24-30 fps, irregular
  timestamps, dropped frames, heavier noise).
- Rows: the raw input; the paper's EMA γ 0.3/0.5/0.8 per frame and Gaussian σ 1 and 5
  frames (offline); EMA with a time constant, One Euro and Kalman, each tuned by
  faceclean.filters.tune (global MSE objective) on the fold's training takes corrupted
  the same way at the same condition (first TUNE_SECONDS of each), never on validation
  takes; the learned FC, GBT and LSTM, each evaluated per fold with a model whose
  config["val_sources"] holds the fold's source (no model: no figure for that fold).
- Columns: MSE (the paper's measure), MSE relative to the raw input on the same takes,
  jitter ratio, lag in ms, blink closure (faceclean.metrics), each a frame-weighted mean
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

from faceclean import dataset, metrics, simulate
from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.filters import Cleaner, make

SEED = 2020
CONDITIONS: dict[str, tuple[str, float | None]] = {  # name -> (preset, fps or preset's)
    "30 fps": ("iphone", 30.0),
    "60 fps": ("iphone", 60.0),
    "120 fps": ("iphone", 120.0),
    "webcam": ("webcam", None),
}
TUNE_SECONDS = 20.0  # s of each training take used to tune the classical filters
QUICK_SECONDS = 6.0  # s of each take in --quick mode
METRICS = ("mse", "rel_mse", "jitter_ratio", "lag_ms", "blink_closure")
FORMATS = {"faceclean-lstm/1": "lstm", "faceclean-fc/1": "fc", "faceclean-gbt/1": "gbt"}

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
LEARNED_ROWS: list[tuple[str, str]] = [("FC", "fc"), ("GBT", "gbt"), ("LSTM", "lstm")]

Progress = Callable[[str], None]


def model_files(extra: Sequence[str | os.PathLike] = ()) -> list[Path]:
    """Candidate checkpoints: ``extra`` files or folders first, then models/folds/*.npz,
    then the shipped models (default.npz, fc.npz, gbt.npz)."""
    from faceclean.settings import MODELS

    out: list[Path] = []
    for p in map(Path, extra):
        if not p.exists():
            raise FacecleanError(f"no such model file or folder: {p}")
        out += sorted(p.glob("*.npz")) if p.is_dir() else [p]
    out += sorted((MODELS / "folds").glob("*.npz"))
    out += [MODELS / f for f in ("default.npz", "fc.npz", "gbt.npz") if (MODELS / f).is_file()]
    return out


def model_config(path: Path) -> dict[str, Any]:
    """A checkpoint's config JSON (without loading its weights into a cleaner)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return json.loads(str(z["config"][()]))
    except (OSError, ValueError, KeyError) as e:
        raise FacecleanError(f"{path}: not a readable model file ({e})") from None


def pick_models(files: Sequence[Path], sources: Sequence[str]) -> dict[str, dict[str, Path]]:
    """method -> held-out source -> the first checkpoint that never saw that source."""
    picked: dict[str, dict[str, Path]] = {m: {} for _, m in LEARNED_ROWS}
    for f in files:
        config = model_config(f)
        method = FORMATS.get(config.get("format", ""))
        if method is None:
            continue
        # Unseen: held out and not trained on (a take-level split lists every source).
        unseen = set(config.get("val_sources", [])) - set(config.get("train_sources", []))
        for s in sorted(unseen & set(sources)):
            picked[method].setdefault(s, f)
    return picked


def corrupted(
    takes: Sequence[dataset.Take], condition: str, seed: int, seconds: float | None = None
) -> list[tuple[Animation, Animation]]:
    """(noisy, truth) ARKit-52 pairs of every take under ``condition``; seeded per take."""
    preset, fps = CONDITIONS[condition]
    pairs = []
    for i, take in enumerate(takes):
        clean = take.animation
        if seconds is not None:
            clean = _head(clean, seconds)
        rng = np.random.default_rng([seed, i])
        params = simulate.sample_params(rng, preset)
        if fps is not None:
            params = dataclasses.replace(params, fps=fps)
        noisy, truth = simulate.apply(clean, params, rng)
        pairs.append((noisy.with_values(noisy.arkit()[0]), truth.with_values(truth.arkit()[0])))
    return pairs


def _head(anim: Animation, seconds: float) -> Animation:
    keep = anim.times <= anim.times[0] + seconds
    return Animation(anim.times[keep], anim.values[keep], anim.names, dict(anim.meta))


def run_streams(cleaner: Cleaner, inputs: Sequence[Animation]) -> list[np.ndarray]:
    """Clean every take; causal cleaners step all takes at once as streams (S, M)."""
    if cleaner.offline:
        return [cleaner.clean(a).values for a in inputs]
    n, s, m = max(a.n_frames for a in inputs), len(inputs), inputs[0].n_channels
    t = np.full((n, s), np.nan)  # past a take's end: missing frames (held, ignored)
    x = np.full((n, s, m), np.nan)
    for j, a in enumerate(inputs):
        t[: a.n_frames, j], x[: a.n_frames, j] = a.times, a.values
    cleaner.reset()
    y = np.stack([cleaner.step(x[i], t[i]) for i in range(n)])  # (N, S, M)
    y[np.isnan(x).all(axis=-1)] = np.nan  # missing frames stay missing (as clean() does)
    return [y[: a.n_frames, j] for j, a in enumerate(inputs)]


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
    """Run the whole protocol; returns a JSON-ready dict (see :func:`markdown`).

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
        for cond in CONDITIONS:
            if progress:
                progress(f"fold {source}, {cond}")
            pairs = corrupted(val, cond, seed, seconds)
            inputs = [noisy for noisy, _ in pairs]
            names = inputs[0].names
            record("Raw input", cond, source, val, _scores([a.values for a in inputs], pairs))
            for label, method, params, _ in FIXED_ROWS:
                outs = run_streams(make(method, params, names=names), inputs)
                record(label, cond, source, val, _scores(outs, pairs))
            tune_pairs = corrupted(train, cond, seed + 1, tune_seconds)
            for label, method in TUNED_ROWS:
                result = tune.tune(method, tune_pairs)
                tuned_params.setdefault(label, {}).setdefault(cond, {})[source] = result.params
                outs = run_streams(result.build(names), inputs)
                record(label, cond, source, val, _scores(outs, pairs))
            for label, method in LEARNED_ROWS:
                path = picked[method].get(source)
                if path is not None:
                    outs = run_streams(_learned(method, path, names), inputs)
                    record(label, cond, source, val, _scores(outs, pairs))
    return {
        "seed": seed,
        "quick": quick,
        "conditions": {c: {"preset": p, "fps": f} for c, (p, f) in CONDITIONS.items()},
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


def _learned(method: str, path: Path, names: Sequence[str]) -> Cleaner:
    key = "path" if method == "lstm" else "model"
    return make(method, {key: str(path)}, names=names)


def _mean(scores: list[dict[str, float]], key: str) -> float:
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
                figs = {k: _mean([sc for _, _, sc in its], k) for k in METRICS if k != "rel_mse"}
                figs["rel_mse"] = figs["mse"] / _mean(base, "mse")
                figs["takes"] = len(its)
                out[g] = figs
            rows.setdefault(label, {})[cond] = out
    return rows


# -- the markdown report -------------------------------------------------------------------

CAUSAL_FILTERS = tuple(label for label, _ in TUNED_ROWS)  # "best tuned causal filter"
TARGET_RELAX = 0.15  # the other conditions: within 15 % of the 60 fps targets


NOTES = [
    "- The paper (its private data, 60 fps) reports MSE raw 0.0173, Gaussian σ5 0.0167 "
    "(0.97× raw), EMA γ0.3 0.0170 (0.98×), FC 0.0461 (2.66×), GBT 0.0451 (2.61×), "
    "LSTM 0.0140 (0.81×). Our absolute MSEs are far smaller (our simulator's artefacts on "
    "calibrated iPhone takes); compare the × raw column.",
    "- FC and GBT follow SPEC section 3: K = 4 derivatives predicted from the input alone "
    "(current value, backward differences ending at the newest and the previous frame), "
    "integrated by the complementary blend with the paper's α_r (0.9 FC, 0.97 GBT) per "
    "frame at 60 fps, applied as α_r^(60 Hz · dt) so the blend's time constant (0.16 s "
    "FC, 0.55 s GBT) is the same at every rate. FC: one "
    "whole-face MLP (2 × 128, ReLU). GBT: scikit-learn histogram GBT per order, shared by "
    "all channels (samples are channels; features plus the channel's group), depth ≤ 5, "
    "30 trees for the first order and 10 for each higher one, run by a numpy tree "
    "walker. Both trained with L_der (orders scaled by their training std) on the fold's "
    'training sources, corrupted with the simulator\'s "mixed" preset at the drawn rate '
    "and resampled ×2 and ×½ (`faceclean train --arch fc|gbt --val-sources SOURCE`).",
    "- Raw input lag and blink figures are not exactly 0 and 1: the simulator saturates "
    "blinks and adds correlated noise and drift, and the lag search aligns what it can.",
]


def _fmt(v: float, digits: int = 3) -> str:
    if v is None or not np.isfinite(v):
        return "–"
    return f"{v:.{digits}g}" if abs(v) < 1000 else f"{v:.0f}"


def targets(results: dict[str, Any], label: str = "LSTM") -> list[tuple[str, dict[str, str]]]:
    """The issue's targets for ``label``, per condition: (target, {condition: text})."""
    rows = results["rows"]
    out: list[tuple[str, dict[str, str]]] = []
    if label not in rows:
        return out
    checks = [
        ("MSE ≤ 0.5× raw", "rel_mse", 0.5, "max"),
        ("MSE ≤ 0.8× best tuned causal filter", "vs_filter", 0.8, "max"),
        ("jitter ratio ≤ 2", "jitter_ratio", 2.0, "max"),
        ("lag < 10 ms", "lag_ms", 10.0, "max"),
        ("blink closure ≥ 0.85", "blink_closure", 0.85, "min"),
    ]
    for name, key, limit, kind in checks:
        cells = {}
        for cond in CONDITIONS:
            fig = rows[label].get(cond, {}).get("all")
            if fig is None:
                cells[cond] = "–"
                continue
            if key == "vs_filter":  # the best filter on the same takes as ``label``
                takes = {(s, n) for s, n, _ in results["per_take"][label][cond]}
                best = min(
                    (
                        _mean(
                            [sc for s, n, sc in results["per_take"][f][cond] if (s, n) in takes],
                            "mse",
                        )
                        for f in CAUSAL_FILTERS
                        if f in rows
                    ),
                    default=float("nan"),
                )
                value = fig["mse"] / best
            else:
                value = fig[key]
            relax = 1.0 if cond == "60 fps" else 1.0 + TARGET_RELAX
            lim = limit * relax if kind == "max" else limit / relax
            ok = value <= lim if kind == "max" else value >= lim
            mark = "met" if ok else "**missed**"
            cells[cond] = f"{_fmt(value)} {mark}" if np.isfinite(value) else "–"
        out.append((name, cells))
    return out


def _findings(rows: dict[str, dict[str, dict]]) -> list[str]:
    """One line per condition: the best causal filter, and each learned row, × raw."""
    out = []
    for cond in CONDITIONS:
        have = [f for f in CAUSAL_FILTERS if f in rows and cond in rows[f]]
        if not have:
            continue
        best = min(have, key=lambda f: rows[f][cond]["all"]["mse"])
        parts = [f"best causal filter {best} {_fmt(rows[best][cond]['all']['rel_mse'])}× raw"]
        for label, _ in LEARNED_ROWS:
            if label in rows and cond in rows[label]:
                parts.append(f"{label} {_fmt(rows[label][cond]['all']['rel_mse'])}×")
        out.append(f"- {cond}: " + "; ".join(parts) + ".")
    return out


def markdown(results: dict[str, Any]) -> str:
    """docs/RESULTS.md: header, targets, one table per condition, per-source MSE × raw."""
    rows, folds = results["rows"], results["folds"]
    lines = [
        "# Results",
        "",
        "Generated by `make eval` (`faceclean eval --models benchmarks/models --json "
        "docs/results.json --markdown docs/RESULTS.md`); do not edit by hand. Fold models "
        "live in `benchmarks/models/` (`<arch>-<held-out source>.npz`, trained by "
        "`faceclean train --arch <arch> --val-sources <source> --out ...`)."
        + (" **Quick run (--quick).**" if results["quick"] else ""),
        "",
        f"- **Protocol**: leave one source out. Seed {results['seed']}: every validation take "
        'corrupted by `faceclean.simulate` (preset "iphone" at 30, 60 and 120 fps, the same '
        'artefact draw at each rate; preset "webcam": 24–30 fps, irregular timestamps, '
        "dropped frames, heavier noise).",
    ]
    for s, f in folds.items():
        lines.append(
            f"- **Fold `{s}`**: validation takes {', '.join(f['val_takes'])}; "
            f"{f['train_takes']} training takes from the other sources."
        )
    lines += [
        "- **Tuned filters** (EMA τ, One Euro, Kalman): tuned per fold and condition by "
        "`faceclean.filters.tune` (MSE objective) on the fold's training takes corrupted with "
        f"seed {results['seed'] + 1} (first {TUNE_SECONDS:g} s of each); never on validation "
        "takes.",
        "- **Learned rows**: per fold, a model whose checkpoint config lists the fold's "
        "source as held out and not trained on; a fold without one has no figure (see "
        "the per-source table). Models used:",
    ]
    for method, per in results["models"].items():
        used = ", ".join(f"`{s}`: {Path(p).name}" for s, p in per.items()) or "none found"
        lines.append(f"  - {method}: {used}")
    if results.get("early_stopped"):
        shown = ", ".join(Path(p).name for p in results["early_stopped"])
        lines.append(
            f"  - {shown}: the checkpoint of the epoch with the best validation loss on the "
            "held-out source (early stopping, other simulator seeds than here): its figures "
            "are a little optimistic."
        )
    lines += [
        "- **Columns**: MSE over all channels and frames (the paper's measure); × raw = MSE "
        "over the raw input's MSE on the same takes; jitter = mean squared 2nd "
        "time-derivative, output over truth (1 ideal); lag = delay best aligning output "
        "with truth (0 ideal); blink = output peak over true peak per true blink (1 ideal). "
        "Frame-weighted means over takes, all folds pooled. Gaussian rows are offline "
        "(non-causal); everything else is causal.",
        "",
        "## Targets (issue 4), LSTM on unseen sources",
        "",
        "At 60 fps as stated; at 30, 120 fps and webcam the same targets relaxed by 15 % "
        "(the paper's frame-rate independence claim, measured).",
        "",
    ]
    checks = targets(results)
    if checks:
        lines.append("| target | " + " | ".join(CONDITIONS) + " |")
        lines.append("|---|" + "---|" * len(CONDITIONS))
        for name, cells in checks:
            lines.append(f"| {name} | " + " | ".join(cells[c] for c in CONDITIONS) + " |")
    else:
        lines.append("No LSTM model that held out a source was found: no LSTM figures yet.")
    lines += ["", *_findings(rows)]
    for cond in CONDITIONS:
        lines += ["", f"## {cond}", ""]
        lines.append("| method | MSE | × raw | jitter | lag ms | blink |")
        lines.append("|---|---|---|---|---|---|")
        for label, by_cond in rows.items():
            fig = by_cond.get(cond, {}).get("all")
            if fig is None:
                continue
            cells = [f"{fig['mse']:.3g}", _fmt(fig["rel_mse"]), _fmt(fig["jitter_ratio"])]
            cells += [_fmt(fig["lag_ms"], 2), _fmt(fig["blink_closure"])]
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += ["", "## Notes", "", *NOTES]
    lines += ["", "## MSE × raw per held-out source", ""]
    header = [f"{s} {c}" for s in folds for c in CONDITIONS]
    lines.append("| method | " + " | ".join(header) + " |")
    lines.append("|---|" + "---|" * len(header))
    for label, by_cond in rows.items():
        cells = [
            _fmt(by_cond.get(c, {}).get(s, {}).get("rel_mse")) for s in folds for c in CONDITIONS
        ]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


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
