"""The tracker section of docs/RESULTS.md, rendered from ``tracker_eval.evaluate`` and the
still real face (``still``). ``insert(page, section)`` puts it between its markers, so the
rest of RESULTS.md (``faceclean eval``'s tables) is left as it is."""

from __future__ import annotations

from typing import Any

from faceclean.channels import GROUPS

BEGIN, END = "<!-- tracker pairs: begin -->", "<!-- tracker pairs: end -->"


def markdown(result: dict[str, Any], still: dict[str, Any] | None = None,
             extra: dict[str, Any] | None = None) -> str:  # fmt: skip
    """The section: the overall table (MSE ratio to raw per split), per-group MSE, per fold."""
    rows = dict(result["overall"])
    lines = [BEGIN, "", "## MediaPipe in the loop: cleaners judged on pairs no training saw", ""]
    lines += [
        "Rendered ICT faces (unseen identities) performing takes of a source no training saw "
        "(leave one source out), tracked by MediaPipe Face Landmarker; *test* = the training "
        "render settings (studio, webcam), *held-out* = the `window` setting no model saw. "
        f"Pairs: `{result['pairs']}`.",
        "",
        "What this shows and what it does not: every learned row is trained on *rendered* "
        "faces only, and judged here on rendered faces. A real face was checked only for "
        "stillness (the table at the end); no real MediaPipe capture with clean truth exists "
        "here, so the gain on real performances is not measured.",
        "",
    ]
    real = result.get("real")
    if real:
        lines += [
            "Performances from the real ARKit takes (every fold but the synthetic "
            "performers'; the setting of the issue's own measurements):",
            "",
        ]
        lines += _table(real)
        lines += ["", "Every fold, the synthetic performers' too (overall):", ""]
    lines += _table(rows)
    lines += [
        "",
        "The rows: *one-euro* is tuned per fold on its training pairs (a 16-point grid, by "
        "MSE). *calibration + one-euro* measures each test face's levels from its own "
        "calibration clip (`pairs --rom`: 1 s neutral, then 30 poses taking every channel to "
        "its full range, same face, light and camera), as `calibrate --rom` does (offset = "
        "neutral, gain = 1 / (top - neutral), capped at 10), then the fold's One Euro: a "
        "per-channel gain and offset, which cannot undo MediaPipe's cross-channel mixing. "
        "*ridge map* is a per-channel ridge linear map over all raw inputs. *paper LSTM on "
        "pairs* is the paper's derivative LSTM (2 x 128) trained on the fold's pairs on a CPU "
        "budget: 4 epochs of 200-frame chunks without overlap, best epoch by the inner "
        "validation source. *tracker map (ours)* is learned/tracker_map.py fitted per fold, "
        "its detail scale as the fold chose it; *tracker map, detail 0* and *detail 1* are "
        "the same map with the `detail` setting at 0 (the pre-filter's lag left in) and 1 "
        "(all of the fitted detail): what `--set detail=` trades. "
        "The three learned rows train on the same data: the fold's training pairs and their "
        "calibration clips (never a test face's clip).",
    ]
    if result.get("chosen"):
        g_ = lambda v: "none" if v is None else f"{v:g}"  # noqa: E731
        picks = "; ".join(
            f"{g}: pre-filter "
            + (
                "none, "
                if c["pre_filter"] is None
                else "{:g} Hz, beta {:g}, speed {:g} Hz, ".format(*c["pre_filter"])
            )
            + f"shrinkage {g_(c['lam'])}, detail {g_(c['detail_scale'])}, "
            f"blink knee {g_(c['lift_knee'])}"
            + (", its top following the stream" if c.get("lift_top") else "")
            for g, c in result["chosen"].items()
        )
        lines += ["", "What each fold's tracker map chose (leaving each of its sources out): "
                  + picks + "."]  # fmt: skip
    lines += ["", "MSE per channel group (test split):", ""]
    lines += ["| cleaner | " + " | ".join(GROUPS) + " |", "|---|" + "---|" * len(GROUPS)]
    for name, splits in rows.items():
        s = splits.get("test")
        if s is not None:
            cells = [f"{s.get(f'mse_{g}', float('nan')):.4f}" for g in GROUPS]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "Per fold (MSE x raw, test / held-out):", ""]
    names = list(rows)
    lines += ["| left-out source | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for group, fold in result["folds"].items():
        cells = []
        for name in names:
            hit = next((v for k, v in fold.items() if k.split(" (tuned")[0] == name), None)
            cells.append(_ratio(hit, fold))
        lines.append(f"| {group} | " + " | ".join(cells) + " |")
    if extra:
        lines += ["", extra["title"], "", *extra["lines"]]
    if still:
        lines += [
            "",
            "Still real face (scikit-image's `astronaut` photograph, sub-pixel motion and "
            "sensor noise, tracked live; it does not move at all):",
            "",
            "| cleaner | frame-to-frame change | x raw | drift |",
            "|---|---|---|---|",
        ]
        for name, m in still.items():
            lines.append(
                f"| {name} | {m['change']:.5f} | {m['change_ratio']:.2f} | {m['drift']:.4f} |"
            )
    lines += ["", END]
    return "\n".join(lines) + "\n"


def _table(rows: dict[str, Any]) -> list[str]:
    """The rows' MSE (and x raw), blink closure, jitter and lag, per split."""
    lines = [
        "| cleaner | split | MSE | x raw | blink closure | jitter (x truth) | lag ms | pairs |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, splits in rows.items():
        for split in ("test", "held"):
            s = splits.get(split)
            if s is None:
                continue
            raw = rows["raw"][split]["mse"]
            label = "test" if split == "test" else "held-out setting"
            lines.append(
                f"| {name} | {label} | {s['mse']:.4f} | {s['mse'] / raw:.2f} | "
                f"{s['blink_closure']:.2f} | {s['jitter_ratio']:.2f} | {s['lag_ms']:.0f} | "
                f"{s['pairs']} |"
            )
    return lines


def _ratio(hit: dict | None, fold: dict) -> str:
    if hit is None:
        return "-"
    out = []
    for split in ("test", "held"):
        s, raw = hit.get(split), fold["raw"].get(split)
        out.append("-" if s is None or raw is None else f"{s['mse'] / raw['mse']:.2f}")
    return " / ".join(out)


def insert(page: str, section: str, begin: str = BEGIN, end: str = END) -> str:
    """``page`` with the section between its markers replaced (appended when absent)."""
    if begin in page and end in page:
        head, rest = page.split(begin, 1)
        _, tail = rest.split(end, 1)
        return head + section.rstrip("\n") + tail
    return page.rstrip("\n") + "\n\n" + section
