"""learned/map_take.py: the tracker map over a whole take, runs of usual frames at once.

The contract suite (tests/test_contract.py ``whole_take``) proves a compiled take equal to
reset-then-step; here: which path a map takes, that the shipped kind's one pass is the
one that ran, a take whose blocks have missing rows, and the finite check block by block.
"""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.filters import base, compiled
from faceclean.learned import map_take
from faceclean.learned.map_weights import MapWeights
from faceclean.learned.tracker_map import TrackerMap
from faceclean.settings import MODELS


@pytest.fixture
def numba_on(monkeypatch):
    was = compiled.enabled()
    if not compiled.enable(warm=False):
        pytest.skip("numba not installed: a whole take steps in numpy")
    monkeypatch.setattr(compiled, "WHOLE_TAKE_FRAMES", 0)
    yield
    if not was:
        compiled.disable()


def _take(n: int, seed: int = 0, lost_rows=()) -> Animation:
    rng = np.random.default_rng(seed)
    x = np.clip(0.2 + np.cumsum(rng.normal(0, 0.03, (n, 52)), axis=0), 0, 1)
    t = np.cumsum(rng.uniform(0.7, 1.3, n)) / 60.0
    x[list(lost_rows)] = np.nan  # tracking lost: the block is no longer a run of rows
    return Animation(t, x, ARKIT52)


def _stepped(tm: TrackerMap, anim: Animation) -> np.ndarray:
    tm.reset()
    out = np.full_like(anim.values, np.nan)
    for n in np.flatnonzero(anim.valid):
        out[n] = tm.step(anim.values[n], anim.times[n])
    return out


@pytest.mark.parametrize("top", [True, False])
def test_the_shipped_map_and_a_lifted_one_go_in_one_pass_a_mixed_one_apart(
    numba_on, monkeypatch, top
):
    # The blink lift runs inside the one pass (compiled.map_run), its top kept or not;
    # an A beyond each output's own input (a map over every input) goes apart.
    shipped = MapWeights.load(MODELS / "mediapipe.npz")
    a = dict(shipped.arrays)
    a["lift_gain"] = np.where(np.arange(len(a["lift_gain"])) < 2, 3.0, 0.0)  # two lifts
    a["lift_knee"] = np.full(len(a["lift_knee"]), 0.2)
    lifted = MapWeights.build(dict(shipped.config, lift_top=top), a)
    a = dict(shipped.arrays, a=np.array(shipped.arrays["a"]))
    a["a"][0, 1] = 0.1  # eyeBlinkLeft reads eyeLookDownLeft's level
    mixed = MapWeights.build(shipped.config, a)
    for w, kind in ((shipped, True), (lifted, True), (mixed, False)):
        assert (map_take._shipped_kind(TrackerMap(weights=w, names=ARKIT52)) is not None) == kind
    runs = []
    one = compiled.map_run
    monkeypatch.setattr(compiled, "map_run", lambda *a: runs.append(len(a[0])) or one(*a))
    anim = _take(BLOCK_AND_SOME, lost_rows=(100, 101, base.BLOCK + 7))
    wholes = []
    for w, passes in ((shipped, True), (lifted, True), (mixed, False)):
        runs.clear()
        tm = TrackerMap(weights=w, names=ARKIT52)
        wholes.append(tm.clean(anim).values)
        np.testing.assert_allclose(wholes[-1], _stepped(tm, anim), rtol=0, atol=1e-12)
        assert np.isnan(wholes[-1][[100, 101, base.BLOCK + 7]]).all()  # lost rows stay lost
        assert (sum(runs) > 0.9 * len(anim.times)) == passes, sum(runs)
    assert np.nanmax(np.abs(wholes[1][:, 1] - wholes[0][:, 1])) > 0.05  # the lift lifted


BLOCK_AND_SOME = base.BLOCK + 500


def test_an_output_lost_in_a_run_is_refused_and_nothing_returned(numba_on, monkeypatch):
    """The finite check counts each block as it is written (filters/base.py's rule: a
    cleaner that erases data must not write a file)."""
    one, calls = compiled.map_run, []

    def loses_a_cell(p, *rest):
        one(p, *rest)
        p[len(p) // 2, 3] = np.nan
        calls.append(len(p))
        return p

    monkeypatch.setattr(compiled, "map_run", loses_a_cell)
    tm = TrackerMap(model=MODELS / "mediapipe.npz", names=ARKIT52)
    with pytest.raises(FacecleanError, match=r"not finite in (\d+) of \d+ cells") as e:
        tm.clean(_take(BLOCK_AND_SOME))  # one cell in each pass
    assert len(calls) >= 2 and f"in {len(calls)} of" in str(e.value)
