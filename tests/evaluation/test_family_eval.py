"""evaluation/family_eval.py's pooling by kind of performance: the real performers' takes
apart from the made-up performers', every held-out family together and each apart, in the
table too."""

from __future__ import annotations

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.datasets.paired import Pair
from faceclean.evaluation import family_eval

NAMES = tuple(n for n in ARKIT52 if n != "tongueOut")


def _pair(name: str, group: str, family: str, seed: int) -> Pair:
    rng = np.random.default_rng(seed)
    t = np.arange(90) / 30.0
    y = np.clip(0.3 + 0.2 * np.sin(t[:, None] * rng.uniform(1, 3, len(NAMES))), 0, 1)
    x = np.clip(y + rng.normal(0, 0.05, y.shape), 0, 1)
    return Pair(name, Animation(t, x, NAMES), Animation(t, y, NAMES), group, "studio",
                family=family)  # fmt: skip


def test_kinds_pool_real_and_made_up_performances_over_families():
    pairs = [_pair("a", "alexdjulin", "painted", 1), _pair("b", "independent", "painted", 2),
             _pair("c", "neurosync", "photo", 3), _pair("d", "synthetic", "photo", 4)]  # fmt: skip
    halved = lambda p: p.tracked.with_values((p.tracked.values + p.truth.values) / 2)  # noqa: E731
    per = {fam: {"raw": [(p.tracked, p) for p in pairs if p.family == fam],
                 "half": [(halved(p), p) for p in pairs if p.family == fam]}
           for fam in ("painted", "photo")}  # fmt: skip
    kinds = family_eval._kinds(per)
    assert sorted(kinds) == ["made-up", "real"]
    for kind in kinds.values():  # half of raw's error: a quarter of its square
        assert kind["raw"]["pairs"] == 2
        assert np.isclose(kind["half"]["mse"] / kind["raw"]["mse"], 0.25)
    fams = {f: {r: family_eval.scores(v) for r, v in rows.items()} for f, rows in per.items()}
    apart = family_eval._family_and_kind(per)
    assert {f: sorted(k) for f, k in apart.items()} == {
        "painted": ["made-up", "real"],
        "photo": ["made-up", "real"],
    }
    assert apart["photo"]["real"]["raw"]["pairs"] == 1  # neurosync's pair, photo alone
    assert np.isclose(apart["photo"]["real"]["raw"]["mse"],
                      family_eval.scores(per["photo"]["raw"][:1])["mse"])  # fmt: skip
    result = {"families": fams, "neutral": {}, "kinds": kinds, "pairs": {}, "gaze": True,
              "channels": family_eval._channels(per), "family_kinds": apart}  # fmt: skip
    table = family_eval.markdown(result)
    assert "| real | half | 0.25 |" in table and "| made-up | half | 0.25 |" in table
    assert "| photo | real | half | 0.25 |" in table
