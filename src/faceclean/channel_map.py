"""One channel list mapped onto another's columns by ``channels.key`` (canonical name,
else the name itself): every module that lines up channels by name uses it.

For a learned model: input columns the model lacks pass through untouched; model channels
the input lacks are fed the model's own last output (so their corrective derivative is
zero).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from faceclean.channels import channel_key


class ChannelMap:
    """Wanted (model) channel j <- column ``src[j]`` of ``names`` (-1 when absent; the
    first column of a name given twice)."""

    def __init__(self, model: Sequence[str], names: Sequence[str]) -> None:
        cols: dict[str, int] = {}
        for j, n in enumerate(names):
            cols.setdefault(channel_key(n), j)
        src = np.array([cols.get(channel_key(n), -1) for n in model], dtype=np.intp)
        self.src = src
        self.have = np.flatnonzero(src >= 0)  # model channels fed from the input
        self.lack = np.flatnonzero(src < 0)  # model channels fed their last output
        self.cols = src[self.have]  # their input columns
        self.identity = len(model) == len(names) and bool(np.array_equal(src, np.arange(len(src))))

    def gather(self, x: np.ndarray, y_model: np.ndarray, out: np.ndarray) -> None:
        """Input frames x (S, len(names)) -> ``out`` (S, M) in model order; y_model (S, M)
        is the model's last output (fed for the channels the input lacks)."""
        if self.identity:
            np.copyto(out, x, casting="unsafe")
            return
        out[:, self.have] = x[:, self.cols]
        out[:, self.lack] = y_model[:, self.lack]

    def scatter(self, x: np.ndarray, y_model: np.ndarray) -> np.ndarray:
        """Output frames (S, len(names)) float64: x with the model's channels from y_model."""
        if self.identity:
            return y_model.astype(np.float64)
        out = np.array(x, dtype=np.float64)
        out[:, self.cols] = y_model[:, self.have]
        return out


def span(src: np.ndarray) -> slice | None:
    """Indices ``src`` as a slice where they run (a view for numpy, no copy), else None."""
    n = len(src)
    if n and src[0] >= 0 and np.array_equal(src, np.arange(src[0], src[0] + n)):
        return slice(int(src[0]), int(src[0]) + n)
    return None


def columns(j: np.ndarray, width: int) -> np.ndarray | slice | None:
    """Columns j of ``width``: None for all of them in order, a slice where they run."""
    run = span(j)
    return None if run == slice(0, width) else run or j
