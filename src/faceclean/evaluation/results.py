"""docs/RESULTS.md from :func:`faceclean.evaluation.evaluate.evaluate`'s results: the header (seed,
takes, folds, models), the issue's targets met or missed, one table per condition in the
layout of the paper's Tables 1 and 2, and MSE × raw per held-out source."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from faceclean.evaluation.evaluate import CONDITIONS, LEARNED_ROWS, TUNE_SECONDS, TUNED_ROWS, _mean

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
        "corrupted by `faceclean.evaluation.simulate` "
        '(preset "iphone" at 30, 60 and 120 fps, the same '
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
