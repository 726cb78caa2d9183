"""Fitting the tracker map on pairs: ridge recovers a linear map, the hidden layer what is
not linear, and ``train --pairs`` writes a model ``clean --model`` runs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from faceclean import io
from faceclean.animation import Animation
from faceclean.datasets import paired
from faceclean.datasets.performer import perform
from faceclean.evaluation.metrics import lag_ms
from faceclean.learned.tracker_map import TrackerMap
from faceclean.neural import tracker_map as fit

NAMES = ("eyeBlinkLeft", "eyeBlinkRight", "jawOpen", "mouthSmileLeft")


def pairs(n, seed, tracker):
    out = []
    for k in range(n):
        truth = perform(8.0, seed + k, fps=30.0)
        y = np.stack([truth.channel(c) for c in NAMES], axis=1)
        x = tracker(y)
        group = f"g{k % 2}"
        out.append(paired.Pair(f"p{k}", Animation(truth.times, x, NAMES),
                               Animation(truth.times, y, NAMES), group, "studio"))  # fmt: skip
    return out


def test_ridge_recovers_a_gain_and_offset():
    train = pairs(3, 0, lambda y: 0.6 * y + 0.05)
    w = fit.fit_ridge(train, lams=(1e-9,))
    test = pairs(1, 50, lambda y: 0.6 * y + 0.05)[0]
    out = TrackerMap(weights=w, names=NAMES).clean(test.tracked).values
    np.testing.assert_allclose(out, test.truth.arkit(NAMES)[0], atol=2e-3)


def test_the_hidden_layer_learns_what_a_linear_map_cannot():
    squash = lambda y: np.sqrt(y) * 0.7  # noqa: E731 - a tracker that reads every level too high
    train, val = pairs(4, 0, squash), pairs(2, 20, squash)
    test = pairs(2, 40, squash)

    def mse(w):
        errs = []
        for p in test:
            out = TrackerMap(weights=w, names=NAMES).clean(p.tracked).values
            errs.append(np.mean((out - p.truth.arkit(NAMES)[0]) ** 2))
        return float(np.mean(errs))

    ridge = fit.fit_ridge(train)
    mapped = fit.fit(train, val, hidden=16, epochs=40, prefilters=[(30.0, 0.0, 1.0)])
    raw = float(np.mean([np.mean((p.tracked.values - p.truth.values) ** 2) for p in test]))
    assert mse(ridge) < raw
    assert mse(mapped) < 0.5 * mse(ridge)


def test_train_pairs_writes_a_model_that_cleans(tmp_path):
    folder = tmp_path / "pairs"
    folder.mkdir()
    for p in pairs(4, 0, lambda y: 0.7 * y + 0.03):
        io.save(p.tracked, folder / f"{p.name}.raw.csv")
        io.save(p.truth, folder / f"{p.name}.clean.csv")
    model = tmp_path / "m.npz"
    cli = [sys.executable, "-m", "faceclean"]
    r = subprocess.run([*cli, "train", "--pairs", str(folder), "--arch", "ridge", "--out",
                        str(model)], capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 0, r.stderr
    out = tmp_path / "o.csv"
    r = subprocess.run([*cli, "clean", str(folder / "p0.raw.csv"), "-o", str(out), "--model",
                        str(model)], capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 0, r.stderr
    cleaned = io.load(out).arkit(NAMES)[0]
    truth = io.load(folder / "p0.clean.csv").arkit(NAMES)[0]
    raw = io.load(folder / "p0.raw.csv").arkit(NAMES)[0]
    assert np.mean((cleaned - truth) ** 2) < 0.1 * np.mean((raw - truth) ** 2)  # levels mapped
    r = subprocess.run([*cli, "train", "--pairs", str(tmp_path / "none"), "--out",
                        str(model)], capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 2 and "no such folder of pairs" in r.stderr
    assert "Traceback" not in r.stderr


def test_train_pairs_trains_on_the_calibration_clips_too(tmp_path):
    from faceclean.learned.tracker_map import MapWeights

    folder = tmp_path / "pairs"
    folder.mkdir()
    frames = 0
    for k, p in enumerate(pairs(4, 10, lambda y: 0.7 * y + 0.03)):
        io.save(p.tracked, folder / f"{p.name}.tracked.csv")
        io.save(p.truth, folder / f"{p.name}.truth.csv")
        frames += len(p.tracked.times)
        if k < 3:  # the fourth pair has no clip
            clip = pairs(1, 100 + k, lambda y: 0.7 * y + 0.03)[0]
            io.save(clip.tracked, folder / f"{p.name}.rom.tracked.csv")
            io.save(clip.truth, folder / f"{p.name}.rom.truth.csv")
            frames += len(clip.tracked.times)
    model = tmp_path / "m.npz"
    cli = [sys.executable, "-m", "faceclean", "train", "--pairs", str(folder)]
    r = subprocess.run([*cli, "--arch", "ridge", "--out", str(model)], capture_output=True,
                       text=True)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "and 3 calibration clips" in r.stdout
    assert MapWeights.load(model).config["frames"] == frames  # every pair's and clip's frame


def test_the_choice_is_made_leaving_each_source_out():
    """Three sources: the pre-filter and shrinkage are chosen leaving one source out in
    turn, each scored on a fit that never saw it; a noisy tracker gets a pre-filter."""
    rng = np.random.default_rng(3)
    noisy = lambda y: 0.7 * y + 0.05 + rng.normal(0, 0.04, y.shape)  # noqa: E731
    pool = []
    for g in range(3):
        for p in pairs(2, 10 * g, noisy):
            pool.append(paired.Pair(p.name + f"s{g}", p.tracked, p.truth, f"src{g}", "studio"))
    seen = []
    pres = (None, (2.0, 0.5, 1.0))
    w = fit.fit(pool[:4], pool[4:], prefilters=pres, lams=(1e-2, 1.0), report=seen.append,
                knees=(None,), details=(0.0, 0.5))  # the lift: its own test  # fmt: skip
    cands = [e for e in seen if e.get("event") == "candidate"]
    assert len(cands) == 6 and all(e["cv"] == 3 for e in cands)  # every candidate, 3 sources
    assert all(e["detail"] == 0 for e in cands if e["pre"] is None)  # no filter, no detail
    assert w.config["selected"] == "leave one source out: src0, src1, src2"
    assert w.config["prefilter"] and w.arrays["min_cutoff"][0] == 2.0  # the jitter's price
    score = lambda e: e["val_mse"] * (1 + max(0, e["jitter"] / 1.5 - 1))  # noqa: E731
    top = min(map(score, cands))
    near = [e for e in cands if score(e) <= top * (1 + fit.TIE)]  # equal within noise
    calm = [e for e in near if e["worst_jitter"] <= fit.JITTER_BUDGET]  # on every source
    # the least lag of those within the jitter budget (their lag alone measured), else the
    # smoothest
    key = lambda e: (e["pre"], e["lam"], e["detail"])  # noqa: E731
    lags = {key(e): e["lag_ms"] for e in seen if e.get("event") == "candidate_lag"}
    assert set(lags) == {key(e) for e in calm} and all(np.isfinite(list(lags.values())))
    chosen = min(calm, key=lambda e: lags[key(e)]) if calm else min(near, key=lambda e: e["jitter"])
    assert all(e["worst_jitter"] >= e["jitter"] for e in cands)
    assert w.config["lam"] == chosen["lam"] and w.config["val_mse"] == chosen["val_mse"]
    assert w.config["detail_scale"] == chosen["detail"]
    assert w.config["deadband"] == fit.DEADBAND
    # a source's score comes from the others' fit: it differs from the score with it in
    inside = fit.score(w, fit.features(w, pool[:2]))[0]
    alone = fit.fit(pool[2:], [], prefilters=[(2.0, 0.5, 1.0)], lams=(w.config["lam"],), cv=False)
    held_out = fit.score(alone, fit.features(alone, pool[:2]))[0]
    assert inside < held_out


def test_the_detail_gives_back_the_timing_the_pre_filter_took():
    """A tracker that reads 0.7 y + 0.05 without noise, behind a slow pre-filter: the
    truth is (u + e - 0.05) / 0.7, so the detail's unshrunk gain is the map's own 1 / 0.7,
    the full detail is chosen, and the output has neither the filter's lag nor its error.
    Training's prediction, detail included, is the cleaner's output."""
    scale = lambda y: 0.7 * y + 0.05  # noqa: E731
    pool = [paired.Pair(p.name + f"s{g}", p.tracked, p.truth, f"src{g}", "studio")
            for g in range(3) for p in pairs(2, 10 * g, scale)]  # fmt: skip
    seen = []
    # the map over every input, with an offset (the map by group has none: map_groups.py)
    w = fit.fit(pool[:4], pool[4:], prefilters=[(1.0, 0.0, 1.0)], lams=(1e-3,),
                knees=(None,), details=(0.0, 1.0), report=seen.append,
                structured=False)  # fmt: skip
    cands = {e["detail"]: e for e in seen if e.get("event") == "candidate"}
    assert cands[1.0]["val_mse"] < 0.1 * cands[0.0]["val_mse"]
    assert w.config["detail_scale"] == 1.0
    np.testing.assert_allclose(w.arrays["detail"], 1 / 0.7, rtol=0.02)
    test = pairs(1, 70, scale)[0]
    out = TrackerMap(weights=w, names=NAMES).clean(test.tracked).values
    assert np.abs(out - test.truth.values).max() < 0.03  # the deadband: 0.01 of it
    late = TrackerMap(weights=w, names=NAMES, detail=0.0).clean(test.tracked).values
    t, y = test.truth.times, test.truth.values
    assert lag_ms(t, out, y) < 0.2 * lag_ms(t, late, y) and lag_ms(t, late, y) > 50
    f = fit.features(w, [test])[0]
    np.testing.assert_allclose(fit.predict(w, f.u, f.r, f.e), out, atol=1e-12)


def test_the_fit_scores_the_blinks_against_the_raw_tracker():
    """score(closure=True) ends with the blink outputs' MSE over their raw inputs': a map
    whose output is the raw frame (A = I, detail 1) scores 1 there; on a tracker that
    reads blinks exactly, a lift of 3 from 0 overshoots every blink (closure past 1) and
    its blinks end worse than raw, while the other outputs are untouched."""
    rng = np.random.default_rng(5)
    test = pairs(2, 30, lambda y: np.clip(y + rng.normal(0, 0.01, y.shape), 0, 1))
    w = fit.blank(NAMES, 0, (1.0, 0.0, 1.0), False)
    w.arrays["detail"] = np.ones(len(NAMES))
    feats = fit.features(w, test)
    mse, _, closure, blinks = fit.score(w, feats, closure=True)
    np.testing.assert_allclose(blinks, 1.0, rtol=1e-9)  # the raw frame itself
    np.testing.assert_allclose(closure, 1.0, atol=0.03)
    lifted = fit.blank(NAMES, 0, (1.0, 0.0, 1.0), False)
    lifted.arrays["detail"] = np.ones(len(NAMES))
    fit._set_lift(lifted, np.array([3.0, 3.0, 0.0, 0.0]), 0.0)
    mse2, _, closure2, blinks2 = fit.score(lifted, feats, closure=True)
    assert closure2 > 1.05 and blinks2 > 1.5 and mse2 > mse


def test_training_scores_the_deadband_the_runtime_runs():
    """fit's frame-by-frame prediction (deadband included) is the cleaner's output."""
    rng = np.random.default_rng(4)
    noisy = lambda y: 0.7 * y + 0.05 + rng.normal(0, 0.01, y.shape)  # noqa: E731
    train = pairs(3, 0, noisy)
    w = fit.fit(train, [], prefilters=[(4.0, 1.0, 1.0)], lams=(1e-2,), cv=False, deadband=0.02)
    assert w.config["deadband"] == 0.02
    test = pairs(1, 30, noisy)[0]
    t, u, r, _, e = fit.features(w, [test])[0]
    want = TrackerMap(weights=w, names=NAMES).clean(test.tracked).values
    np.testing.assert_allclose(fit.predict(w, u, r, e), want, atol=1e-12)
    plain = fit.blank(NAMES, 0, (4.0, 1.0, 1.0), True)
    plain.arrays.update({k: w.arrays[k] for k in ("a", "b", "c")})
    still = np.abs(np.diff(fit.predict(w, u, r), axis=0))
    assert still.mean() < np.abs(np.diff(fit.predict(plain, u, r), axis=0)).mean()


def test_the_blink_lift_is_chosen_leaving_each_source_out():
    """Every knee is scored leaving each source out (MSE x jitter's price x closure's
    price outside CLOSURE_BAND) and the best is taken; the gains fitted on the
    performances undo the tracker's under-read; training's prediction, lift included, is
    the cleaner's output."""
    rng = np.random.default_rng(6)

    def under(y):  # each face's blinks read at their own fraction
        x = 0.7 * y + 0.05 + rng.normal(0, 0.005, y.shape)
        x[:, :2] = rng.uniform(0.2, 0.6) * y[:, :2] + 0.05 + rng.normal(0, 0.005, (len(y), 2))
        return x

    pool = [paired.Pair(p.name + f"s{g}", p.tracked, p.truth, f"src{g}", "studio")
            for g in range(3) for p in pairs(2, 10 * g, under)]  # fmt: skip
    seen = []
    pres, lams = [(8.0, 1.0, 1.0)], (1e-2,)
    w = fit.fit(pool[:4], pool[4:], prefilters=pres, lams=lams, report=seen.append)
    lifts = [e for e in seen if e.get("event") == "lift"]
    want = [(k, t) for k in fit.KNEES for t in fit.TOPS if k is not None or not t]
    assert [(e["knee"], e["top"]) for e in lifts] == want and all(e["cv"] == 3 for e in lifts)
    lo, hi = fit.CLOSURE_BAND

    def score(e):  # the blinks' MSE over raw's priced too: a lift must not take them past raw
        price = max(0.0, lo - e["closure"]) + max(0.0, e["closure"] - hi)
        blinks = 1 + max(0.0, e["blinks"] - 1)
        return e["val_mse"] * (1 + max(0, e["jitter"] / 1.5 - 1)) * (1 + price) * blinks

    best = min(lifts, key=score)
    assert (w.config["lift_knee"], w.config["lift_top"]) == (best["knee"], best["top"])
    assert (w.arrays["lift_gain"][2:] == 0).all()  # blinks only
    none = fit.fit(pool[:4], pool[4:], prefilters=pres, lams=lams, knees=(None,))
    assert none.config["lift_knee"] is None and not none.arrays["lift_gain"].any()
    # the gains: truth / (rise - knee) where an eye closes; a tracker at a quarter reads 4
    # through a low-pass that barely lags (100 Hz), more through the default 4 Hz one
    quarter = [paired.Pair("q", Animation(p.truth.times, 0.25 * p.truth.values, NAMES), p.truth,
                           "src0", "studio") for p in pool[:2]]  # fmt: skip
    feats = fit.features(none, quarter)
    slow = fit._lift_gains(none, feats, 0.0)
    none.config["lift_cutoff"] = 100.0
    gains = fit._lift_gains(none, feats, 0.0)
    np.testing.assert_allclose(gains[:2], 4.0, rtol=0.05)
    assert (gains[2:] == 0).all() and (slow[:2] > gains[:2] + 0.1).all()
    plain = TrackerMap(weights=none, names=NAMES)  # the same linear part, no lift
    fit._set_lift(none, gains, 0.0)
    test = pairs(1, 90, lambda y: 0.25 * y)[0]  # a face whose blinks read at a quarter
    out = TrackerMap(weights=none, names=NAMES).clean(test.tracked).values
    t, u, r, _, e = fit.features(none, [test])[0]
    np.testing.assert_allclose(fit.predict(none, u, r, e, t), out, atol=1e-12)
    before = plain.clean(test.tracked).values
    assert (out[:, :2] >= before[:, :2] - 1e-12).all()
    assert out[:, :2].max() > before[:, :2].max() + 0.1  # a lifted blink
    np.testing.assert_array_equal(out[:, 2:], before[:, 2:])  # the other channels as they were
