"""The tracker map on a look it never saw (issue 34): fitted on pairs of two looks, judged on
a third. Each look's tracker re-mixes gaze its own way (as one renderer's eyes do) and
reads some channels as zero that the truth moves (MediaPipe's jawForward, noseSneer).
Fitting one ridge over every input (the map before issue 34) lifts the zero-read channels
to the training performances' level and makes gaze worse than raw on the new look; the
map fitted by group (neural/map_groups.py) must do neither, and keep a face at rest at
rest."""

from __future__ import annotations

import pytest
from looks import PRE, gaze_ratio, neutral_off, pairs, zero_read_level

from faceclean.neural import map_groups
from faceclean.neural import tracker_map as fit


@pytest.fixture(scope="module")
def fitted():
    train = pairs(1) + pairs(2)
    test = pairs(3)
    by_group = fit.fit(train, [], prefilters=PRE, knees=(None,), structured=True)
    every = fit.fit(train, [], prefilters=PRE, knees=(None,), structured=False)
    return by_group, every, test


@pytest.mark.slow
def test_the_map_by_group_keeps_gaze_no_worse_than_raw_on_a_new_look(fitted):
    by_group, every, test = fitted
    assert gaze_ratio(by_group, test) <= 1.0
    assert by_group.config["structure"]["gaze"][0] in map_groups.KINDS


def test_a_channel_read_as_zero_stays_near_its_input_not_a_training_level(fitted):
    by_group, every, test = fitted
    assert zero_read_level(by_group, test) < 0.02


def test_a_face_at_rest_stays_at_rest(fitted):
    by_group, _, test = fitted
    assert neutral_off(by_group, test) <= 0.05


def test_the_map_over_every_input_fails_what_the_map_by_group_passes(fitted):
    # the method before issue 34, on the same pairs: this fixture tells them apart
    _, every, test = fitted
    assert zero_read_level(every, test) > 0.05 or gaze_ratio(every, test) > 1.0
