"""Guided calibration for ARKit input on a shared iPhone take (issue 35, item 4;
benchmarks/guided_arkit.py): the script performed by a stand-in that reads as the take's
performer does, calibrated as ``calibrate --guided --tracker arkit`` does, lifts the take's
fullest blink to full closure and lowers no blink."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from helpers import REPO, first_take

from faceclean import io
from faceclean.adjust import apply_levels
from faceclean.channels import ARKIT52
from faceclean.guided.fit import guided

sys.path.insert(0, str(REPO / "benchmarks"))
guided_arkit = pytest.importorskip("guided_arkit")


def test_a_stand_in_for_a_takes_performer_calibrates_its_blinks_to_full_closure():
    take = io.load(first_take("sentien"))
    x = np.nan_to_num(take.arkit()[0])
    stand = guided_arkit.stand_in(take, seed=3)
    rate = 1.0 / np.median(np.diff(stand.times))
    assert rate == pytest.approx(1.0 / np.median(np.diff(take.times)), rel=1e-3)  # its rate
    rest = np.median(stand.values[: int(0.9 * rate)], axis=0)  # 1 s late: at rest
    assert np.abs(rest - np.percentile(x, 5, axis=0)).max() < 0.05
    g = guided(stand, "arkit", take="stand-in")
    assert not g.adjust.facts["guided"]["not_seen"]
    after = apply_levels(g.adjust.levels(ARKIT52), x)
    for name in guided_arkit.BLINKS:
        j, peaks = ARKIT52.index(name), guided_arkit.blink_frames(x, name)
        assert len(peaks) >= 3
        assert after[peaks, j].max() >= 0.95 > x[peaks, j].max()  # the fullest closes
        assert np.all(after[peaks, j] >= x[peaks, j] - 1e-9)  # none lower than read
    assert "| sentien/" in "\n".join(guided_arkit.table([{
        "take": "x/sentien/t.csv", "fps": 60.0, "seen": 25, "prompts": 25, "levels": {},
        "blinks": 1, **{k: dict.fromkeys(("read", "cleaned", "calibrated"), 1.0)
                         for k in ("blink_mean", "blink_fullest", "blink_closed")}}]))  # fmt: skip
