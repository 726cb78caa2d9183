"""Animation.valid: a frame is valid where any of its values was read."""

from __future__ import annotations

import numpy as np

from faceclean.animation import Animation


def test_a_frame_is_valid_where_any_value_was_read():
    rng = np.random.default_rng(2)
    values = rng.random((400, 6))
    values[rng.random(values.shape) < 0.4] = np.nan  # lost values everywhere
    values[10] = np.nan  # a lost frame
    values[11, 0] = np.nan  # the first value lost, the others read
    values[11, 1:] = 0.5
    values[12, :-1] = np.nan  # only the last read
    values[12, -1] = 0.2
    valid = Animation(np.arange(400) / 60.0, values, tuple("abcdef")).valid
    np.testing.assert_array_equal(valid, ~np.all(np.isnan(values), axis=1))
    assert not valid[10] and valid[11] and valid[12]
    assert Animation(np.arange(3) / 60.0, np.zeros((3, 0)), ()).valid.all()
