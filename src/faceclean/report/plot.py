"""Curve figures in the manner of the paper's Figures 2-4: one panel per channel.

Input, truth, the main cleaner and compared methods over time (s from the clip's
first frame), weights on the y axis. matplotlib is imported here only, through its
object API (no pyplot, no global backend), and renders with Agg.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from faceclean.channels import channel_key
from faceclean.errors import FacecleanError
from faceclean.evaluation.comparison import Comparison, change
from faceclean.io.atomic import atomic_write

FORMATS = (".png", ".svg", ".pdf")
INPUT_STYLE = {"color": "0.55", "lw": 0.9, "alpha": 0.9}
TRUTH_STYLE = {"color": "black", "lw": 1.3, "ls": "--"}
MAIN_STYLE = {"color": "#1f6fd1", "lw": 1.8}
OTHER_COLORS = ("#e8710a", "#2ca02c", "#9334e6", "#d62728", "#8c564b", "#e52592")


def pick_channels(comp: Comparison, wanted: Sequence[str] | None, count: int = 4) -> list[int]:
    """Column indices of ``wanted`` channels (any spelling); by default the ``count``
    channels the main cleaner changed most."""
    names = comp.input.names
    if not wanted:
        moved = change(comp.input.values, comp.outputs[comp.main].values)
        return [int(j) for j in np.argsort(-moved, kind="stable")[:count]]
    keys = [channel_key(n) for n in names]
    out = []
    for w in wanted:
        if channel_key(w) not in keys:
            raise FacecleanError(f"no channel {w!r} in the input ({len(names)} channels)")
        out.append(keys.index(channel_key(w)))
    return out


def figure(
    comp: Comparison,
    channels: Sequence[str] | None = None,
    start: float | None = None,
    end: float | None = None,
):
    """A matplotlib Figure: one panel per channel, shared time axis in s."""
    from matplotlib.figure import Figure

    cols = pick_channels(comp, channels)
    t = comp.times
    lo = t[0] if start is None else start
    hi = t[-1] if end is None else end
    if not hi > lo:
        raise FacecleanError(f"empty time window: start {lo:g} s, end {hi:g} s")
    span = (t >= lo) & (t <= hi)
    if span.sum() < 2:
        raise FacecleanError(f"fewer than 2 frames between {lo:g} s and {hi:g} s")
    fig = Figure(figsize=(10.0, 1.0 + 2.1 * len(cols)), layout="constrained")
    axes = fig.subplots(len(cols), 1, sharex=True, squeeze=False)[:, 0]
    series = [("input", comp.input.values, INPUT_STYLE)]
    if comp.truth is not None:
        series.append(("truth", comp.truth.values, TRUTH_STYLE))
    for k, (label, out) in enumerate(comp.outputs.items()):
        style = MAIN_STYLE if k == 0 else {"color": OTHER_COLORS[(k - 1) % 6], "lw": 1.3}
        series.append((label, out.values, style))
    for ax, j in zip(axes, cols, strict=True):
        for label, values, style in series:
            ax.plot(t[span], values[span, j], label=label, **style)
        ax.set_title(channel_key(comp.input.names[j]), loc="left", fontsize=10)
        ax.set_ylabel("weight")
        ax.grid(True, color="0.9", lw=0.6)
        ax.set_xlim(lo, hi)
    axes[-1].set_xlabel("time (s)")
    axes[0].legend(loc="upper right", fontsize=8, ncols=min(len(series), 4), framealpha=0.85)
    return fig


def save_figure(
    comp: Comparison,
    path: str | os.PathLike,
    channels: Sequence[str] | None = None,
    start: float | None = None,
    end: float | None = None,
) -> None:
    """Write the figure to PNG, SVG or PDF (by extension), atomically."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise FacecleanError(f"{Path(path).name}: the figure must be {', '.join(FORMATS)}")
    fig = figure(comp, channels, start, end)
    buf = io.BytesIO()
    fig.savefig(buf, format=suffix[1:], dpi=110, metadata=_metadata(suffix))
    atomic_write(path, buf.getvalue())


def _metadata(suffix: str) -> dict[str, str | None]:
    """Reproducible files: no creation date in SVG and PDF."""
    if suffix == ".svg":
        return {"Date": None}
    if suffix == ".pdf":
        return {"CreationDate": None}
    return {}
