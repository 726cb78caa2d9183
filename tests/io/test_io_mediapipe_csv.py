"""MediaPipe blendshape CSVs: their usual time columns read without renaming, and a
cleaned file goes back out with the same columns and time unit."""

from __future__ import annotations

import re

import numpy as np
import pytest

from faceclean import io
from faceclean.errors import FacecleanError

MS = b"""timestamp_ms,_neutral,eyeBlinkLeft,jawOpen
0,0.9,0.1,0.2
33,0.8,0.5,0.25
67,,,
100,0.7,0.2,0.3
"""


def test_timestamp_ms_reads_as_seconds_and_drops_neutral(tmp_path):
    p = tmp_path / "mp.csv"
    p.write_bytes(MS)
    anim = io.load(p)
    assert anim.meta["format"] == "mediapipe"
    assert anim.names == ("eyeBlinkLeft", "jawOpen")  # _neutral is not a blendshape
    np.testing.assert_allclose(anim.times, [0.0, 0.033, 0.067, 0.1])
    assert anim.valid.tolist() == [True, True, False, True]  # the lost face: a missing frame


@pytest.mark.parametrize(
    ("stamps", "scale"),
    [(["0.0", "0.033", "0.066"], 1.0), (["0", "33", "66"], 1e-3), (["0", "33000", "66000"], 1e-6)],
)
def test_timestamp_unit_from_the_frame_step(tmp_path, stamps, scale):
    p = tmp_path / "mp.csv"
    rows = "".join(f"{s},0.5\n" for s in stamps)
    p.write_text("timestamp,jawOpen\n" + rows)
    anim = io.load(p)
    np.testing.assert_allclose(anim.times, np.array([float(s) for s in stamps]) * scale)


def test_written_back_with_its_own_columns_and_unit(tmp_path):
    src, out = tmp_path / "mp.csv", tmp_path / "out.csv"
    src.write_bytes(MS)
    anim = io.load(src)
    io.save(anim.with_values(anim.values * 0.5), out)
    lines = out.read_text().splitlines()
    assert lines[0] == "timestamp_ms,_neutral,eyeBlinkLeft,jawOpen"
    assert lines[1] == "0,0.9,0.05,0.1"  # integer ms stay integers; _neutral untouched
    assert lines[3] == "67,,,"
    again = io.load(out)
    np.testing.assert_allclose(again.values, anim.values * 0.5)


def test_a_plain_take_written_as_mediapipe_gets_timestamp_ms(tmp_path):
    from faceclean.animation import Animation

    anim = Animation(np.array([0.0, 0.5]), np.array([[0.1], [0.2]]), ("jawOpen",))
    out = tmp_path / "o.csv"
    io.save(anim, out, fmt="mediapipe")
    assert out.read_text().splitlines() == ["timestamp_ms,jawOpen", "0.0,0.1", "500.0,0.2"]


def test_a_csv_without_a_time_column_is_refused_in_one_line(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("frame,jawOpen\n0,0.1\n")
    with pytest.raises(FacecleanError, match="MediaPipe CSV"):
        io.load(p)


@pytest.mark.parametrize(
    ("stamps", "said"),
    [
        (["0", "33", "33", "100"], "row 3: time 0.033 s is not after the row before"),
        (["0", "33", "67", "20"], "row 4: time 0.02 s is not after the row before"),
        (["0", "1e300", "2e300"], "row 2: time 1e+297 s is beyond"),
        (["0", "inf", "67"], "row 2 has no finite time"),
        (["0", "33", "-inf"], "row 3 has no finite time"),
    ],
)
def test_repeated_backwards_or_absurd_timestamps_are_refused_in_one_line(tmp_path, stamps, said):
    p = tmp_path / "mp.csv"
    p.write_text("timestamp_ms,jawOpen\n" + "".join(f"{s},0.5\n" for s in stamps))
    with pytest.raises(FacecleanError, match=re.escape(said)) as e:
        io.load(p)
    assert str(e.value).startswith("mp.csv") and "\n" not in str(e.value)


def test_epoch_milliseconds_are_read(tmp_path):
    p = tmp_path / "mp.csv"
    p.write_text("timestamp_ms,jawOpen\n1700000000000,0.5\n1700000000033,0.6\n")
    np.testing.assert_allclose(io.load(p).times, [1.7e9, 1.7e9 + 0.033])
