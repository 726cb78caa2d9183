"""Do no harm: clean real takes in, nothing added; what does a cleaner change?

A cleaner that rewrites a clean performance is broken whatever its MSE on noisy input.
On every real take, as recorded (its own rate and timing, its tracking losses), two
measures compare the cleaned take y with the take x itself:

- level shift: per channel, |mean(y) - mean(x)| over the take's valid frames (weight
  units); the table shows the worst channel over all takes (and which one), and the mean
  of the per-take worsts. An animator sees a shift as a jaw that sits lower.
- blink survival: for every blink of the take (faceclean.metrics' blink detector on the
  take as the truth), the cleaned peak over the take's own peak; mean and minimum.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.datasets.dataset import Take
from faceclean.evaluation import metrics
from faceclean.filters.base import Stepper

TARGET_SHIFT = 0.005  # weight units: no channel's mean may move more (issue 11)


def measure(cleaner: Stepper, take: Take) -> dict[str, Any]:
    """Level shift per channel and blink survival of one cleaned clean take."""
    x, present = take.animation.arkit()
    anim = take.animation.__class__.from_arkit(take.animation.times, x)
    y = cleaner.clean(anim).values
    ok = np.isfinite(x).all(1) & np.isfinite(y).all(1)
    shift = np.abs(y[ok].mean(0) - x[ok].mean(0))  # (52,)
    shift[~present] = 0.0
    worst = int(np.argmax(shift))
    peaks = metrics.blink_peaks(anim.times[ok], y[ok], x[ok], ARKIT52)
    return {
        "take": f"{take.source}/{take.name}",
        "max_shift": float(shift[worst]),
        "channel": ARKIT52[worst],
        "blinks": len(peaks),
        "blink_mean": float(np.mean(peaks)) if len(peaks) else float("nan"),
        "blink_min": float(np.min(peaks)) if len(peaks) else float("nan"),
    }


def table(
    cleaners: dict[str, Callable[[Take], Stepper | None]], takes: Sequence[Take]
) -> dict[str, dict[str, Any]]:
    """label -> pooled figures over the takes its factory gives a cleaner for (a learned
    fold model is only run on the source it never saw: the factory returns None else)."""
    out: dict[str, dict[str, Any]] = {}
    for label, factory in cleaners.items():
        rows = []
        for take in takes:
            c = factory(take)
            if c is not None:
                rows.append(measure(c, take))
        if not rows:
            continue
        worst = max(rows, key=lambda r: r["max_shift"])
        peaks_mean = [r["blink_mean"] for r in rows if r["blinks"]]
        peaks_min = [r["blink_min"] for r in rows if r["blinks"]]
        out[label] = {
            "takes": len(rows),
            "max_shift": worst["max_shift"],
            "where": f"{worst['channel']} in {worst['take']}",
            "mean_take_shift": float(np.mean([r["max_shift"] for r in rows])),
            "blinks": int(sum(r["blinks"] for r in rows)),
            "blink_mean": float(np.mean(peaks_mean)) if peaks_mean else float("nan"),
            "blink_min": float(np.min(peaks_min)) if peaks_min else float("nan"),
            "passes": worst["max_shift"] <= TARGET_SHIFT,
            "per_take": rows,
        }
    return out
