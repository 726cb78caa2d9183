"""How the map's candidates are scored on their folds (neural/map_folds.py): every
performance counts alike, as the geometric mean of each one's MSE x raw."""

from __future__ import annotations

import numpy as np
from looks import NAMES, PRE, habits, pairs

from faceclean.learned.tracker_map import TrackerMap
from faceclean.neural import map_features, map_folds, map_rises


def test_the_typical_mse_is_the_geometric_mean_of_each_performance_as_the_runtime_cleans_it():
    train = pairs(1) + pairs(2)
    w = map_rises.fit(train, prefilters=PRE, lams=(0.01,), knees=(None,), deadbands=(0.01,),
                      noise_bands=(0.0,), own_rise=())  # fmt: skip
    folds = map_folds.folds(train)
    feats = map_features.features(w, train)
    fits = map_rises._fold_fits(w, train, [map_rises._moments(f) for f in feats], folds, 0.01)
    cv = map_folds.cross_validate(w, feats, folds, fits)
    logs, pooled = [], []
    for key, idx in folds.items():
        if key.endswith("neutral"):
            continue
        map_features.set_linear(w, *fits[key])
        num = den = 0.0
        for i in idx:  # the runtime, frame by frame, on a pair its fold's fit never saw
            p = train[i]
            out = TrackerMap(weights=w, names=NAMES).clean(p.tracked).values
            e, e0 = (float(((v - p.truth.values) ** 2).sum()) for v in (out, p.tracked.values))
            logs.append(np.log(e / e0))
            num, den = num + e, den + e0
        pooled.append(num / den)
    assert len(logs) > len(pooled) >= 4
    np.testing.assert_allclose(cv.typical, np.exp(np.mean(logs)), rtol=1e-6)
    np.testing.assert_allclose(cv.mse, np.mean(pooled), rtol=1e-6)


def _candidate(typical: float, pooled: float, jitter: float = 1.0, lag: float = 20.0):
    return (map_folds.Scored(pooled, jitter, lag, {}, {}, 0.0, None, typical), typical)


def test_the_choice_is_made_on_the_judged_mse_then_on_the_price():
    # pooled, the first wins; performance by performance, the second
    loose, stiff = _candidate(0.60, 0.50), _candidate(0.55, 0.60)
    assert map_rises._choose([loose, stiff], "all")[1] == 0.60
    assert map_rises._choose([loose, stiff], "typical")[1] == 0.55
    # within 1 % of the best typical MSE, the lower jitter (priced past its budget) wins
    calm = _candidate(0.554, 0.60, jitter=1.0)
    jumpy = _candidate(0.550, 0.60, jitter=3.0 * map_rises.JITTER_BUDGET)
    assert map_rises._choose([jumpy, calm], "typical")[1] == 0.554


def test_each_performance_alike_and_a_harder_shrink_across_groups_keep_a_real_jaw_still():
    # made-up performers move jawLeft with mouthLeft (another group); real ones never move
    # the jaw. Pooled, with neighbours shrunk alike, the fit keeps the habit; judged on
    # each performance alike with another group shrunk 10x harder, the real jaw moves less.
    train = habits({"jawLeft": "mouthLeft"})
    jaw = NAMES.index("jawLeft")
    kw = dict(prefilters=PRE, lams=(0.003, 0.03), own_rise=(), knees=(None,),
              noise_bands=(0.0,), deadbands=(0.01,), harm_real=None)  # fmt: skip
    loose = map_rises.fit(train, judge="all", cross_group=1.0, **kw)
    stiff = map_rises.fit(train, judge="typical", cross_group=10.0, **kw)
    assert stiff.config["cross_group"] == 10.0 and stiff.config["judge"] == "typical"
    faces = [p for p in train if p.group == "src0"]
    out = lambda w, p: TrackerMap(weights=w, names=NAMES).clean(p.tracked).values  # noqa: E731
    moved = [max(float(np.abs(out(w, p)[:, jaw]).mean()) for p in faces) for w in (loose, stiff)]
    assert moved[1] < moved[0]
