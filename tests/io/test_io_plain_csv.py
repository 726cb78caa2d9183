"""Plain CSV: exact round trips (repr floats), missing frames, passthrough columns."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.io import detect, load, save
from faceclean.settings import takes_dir

TAKES = sorted(takes_dir().glob("*/*.csv")) if takes_dir() else []
needs_takes = pytest.mark.skipif(not TAKES, reason="../shared/data/arkit_takes is absent")


@needs_takes
@pytest.mark.parametrize("name", ["alexdjulin/apfel.csv", "neurosync/Happy.csv"])
def test_real_take_round_trip_exact(tmp_path, name):
    src = load(takes_dir() / name)
    out = tmp_path / "plain.csv"
    save(src, out, fmt="csv")
    assert detect(out) == "csv"
    back = load(out)
    assert back.names == src.names
    assert np.array_equal(back.times, src.times)
    assert np.array_equal(back.values, src.values, equal_nan=True)
    assert np.array_equal(back.valid, src.valid)
    # written again, the text is stable
    again = tmp_path / "again.csv"
    save(back, again)
    assert again.read_bytes() == out.read_bytes()


def test_byte_literal_missing_frame_and_unknown_column(tmp_path):
    path = tmp_path / "p.csv"
    path.write_bytes(b"jawOpen,time,myCustom\n0.5,0.0,7\n,0.0333,\n0.25,0.0667,-1.5\n")
    anim = load(path)
    assert anim.names == ("jawOpen", "myCustom")
    np.testing.assert_array_equal(anim.times, [0.0, 0.0333, 0.0667])
    assert np.isnan(anim.values[1]).all() and not anim.valid[1]
    assert anim.values[2, 1] == -1.5
    out = tmp_path / "o.csv"
    save(anim, out)
    assert out.read_bytes() == b"time,jawOpen,myCustom\n0.0,0.5,7.0\n0.0333,,\n0.0667,0.25,-1.5\n"


def test_repr_exact_floats(tmp_path):
    values = np.array([[0.1 + 0.2, 1 / 3, 1e-300, np.nan]])
    anim = Animation([1 / 7], values, ("a", "b", "c", "d"))
    out = tmp_path / "r.csv"
    save(anim, out)
    back = load(out)
    assert back.times[0] == 1 / 7
    assert np.array_equal(back.values, values, equal_nan=True)


@pytest.mark.parametrize(
    "text, message",
    [
        (b"time,a\n0.0,1\n0.1\n", "fields"),
        (b"time,a\n0.0,x\n", "not a number"),
        (b"time,a\n,1\n", "finite time"),
    ],
)
def test_bad_plain_csv(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_bytes(text)
    with pytest.raises(FacecleanError, match=message):
        load(path)


def test_garbage_csv_is_neither_format(tmp_path):
    path = tmp_path / "garbage.csv"
    path.write_bytes(b"\x00\x01hello,world\n")
    with pytest.raises(FacecleanError, match="not a Live Link"):
        load(path)
