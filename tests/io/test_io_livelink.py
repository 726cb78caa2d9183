"""Live Link Face CSV: byte-exact round trips on the real takes, and on byte literals."""

from __future__ import annotations

import io

import numpy as np
import pytest

from faceclean.errors import FacecleanError
from faceclean.io import detect, load, save
from faceclean.io import livelink_csv as ll
from faceclean.settings import takes_dir

TAKES = sorted(takes_dir().glob("*/*.csv")) if takes_dir() else []
needs_takes = pytest.mark.skipif(not TAKES, reason="../shared/data/arkit_takes is absent")

HEADER = b"Timecode,BlendshapeCount,JawOpen,EyeBlinkLeft,HeadYaw"


def _bytes(anim) -> bytes:
    f = io.BytesIO()
    ll.write(anim, f)
    return f.getvalue()


@needs_takes
def test_all_takes_round_trip_byte_identical():
    assert len(TAKES) >= 13  # takes may be added to the shared folder
    for path in TAKES:
        anim = load(path)
        assert anim.meta["format"] == "livelink"
        assert anim.n_channels == 52
        assert anim.meta["pose"].shape == (anim.n_frames, 9)
        assert _bytes(anim) == path.read_bytes(), path.name


@needs_takes
def test_apfel_missing_rows_kept():
    path = takes_dir() / "alexdjulin" / "apfel.csv"
    anim = load(path)
    assert (~anim.valid).sum() == 35
    assert np.isnan(anim.meta["pose"][~anim.valid]).all()
    # the times of missing rows still come from their timecodes: increasing throughout
    assert np.all(np.diff(anim.times) > 0)
    # a changed copy keeps every missing line as it was
    out = _bytes(anim.with_values(np.clip(anim.values + 0.01, 0, 2)))
    src_lines = path.read_bytes().split(b"\n")
    out_lines = out.split(b"\n")
    assert len(out_lines) == len(src_lines)
    empty = [k for k, line in enumerate(src_lines) if line.endswith(b",0")]
    assert len(empty) == 35
    assert all(out_lines[k] == src_lines[k] for k in empty)


@needs_takes
def test_names_are_the_files_and_columns_map_by_name():
    anim = load(TAKES[0])
    assert anim.names[15:17] == ("JawRight", "JawLeft")  # the app's order, as spelled
    header = TAKES[0].read_bytes().split(b"\n", 1)[0].split(b",")
    first = TAKES[0].read_bytes().split(b"\n")[1].split(b",")
    col = header.index(b"JawLeft")
    assert anim.channel("jawLeft")[0] == float(first[col])


def test_byte_literal_crlf_no_final_newline_and_missing_row(tmp_path):
    text = (
        HEADER + b"\r\n"
        b"23:59:59:59.500,3,0.1000,0.2000,0.5000\r\n"
        b"00:00:00:00.500,0\r\n"
        b"00:00:00:01.500,3,0.3000,0.4000,-0.2500"
    )
    path = tmp_path / "take.csv"
    path.write_bytes(text)
    assert detect(path) == "livelink"
    anim = load(path)
    # wrap past midnight: one frame (1/60 s) after 23:59:59:59.5, then one more
    np.testing.assert_allclose(anim.times, [0.0, 1 / 60, 2 / 60], atol=1e-9)
    assert anim.names == ("JawOpen", "EyeBlinkLeft")
    assert np.isnan(anim.values[1]).all()
    assert anim.meta["pose_names"] == ("HeadYaw",)
    assert _bytes(anim) == text
    # only the changed value's text changes, with the source's 4 decimals
    values = anim.values.copy()
    values[2, 1] = 0.123456
    assert _bytes(anim.with_values(values)) == text.replace(b"0.4000", b"0.1235")


def test_nan_keeps_text_and_unknown_extension(tmp_path):
    path = tmp_path / "t.csv"
    path.write_bytes(HEADER + b"\n00:00:01:00.000,3,0.5000000000,0.2500000000,0.1\n")
    anim = load(path)
    values = anim.values.copy()
    values[0, 0] = np.nan
    values[0, 1] = -1e-13
    assert _bytes(anim.with_values(values)) == path.read_bytes().replace(
        b"0.2500000000", b"0.0000000000"
    )


def test_timecode_text_round_trip():
    for s in (0.0, 1 / 60, 45296.123 / 1.0, 86399.99):
        assert abs(ll.timecode_seconds(ll.timecode_text(s)) - s) < 1e-4
    assert ll.timecode_seconds(b"14:58:02:44.643") == pytest.approx(
        14 * 3600 + 58 * 60 + 2 + 44.643 / 60
    )
    with pytest.raises(FacecleanError):
        ll.timecode_seconds("12:00")


def test_fresh_file_from_another_format(tmp_path):
    from faceclean.animation import Animation

    rng = np.random.default_rng(0)
    anim = Animation.from_arkit(np.arange(5) / 30.0, rng.random((5, 52)))
    anim.values[2] = np.nan
    out = tmp_path / "fresh.csv"
    save(anim, out, fmt="livelink")
    back = load(out)
    assert back.meta["format"] == "livelink"
    assert back.names == ll.ORDER
    got, present = back.arkit()
    assert present.all()
    np.testing.assert_allclose(got, anim.values, atol=1e-10)
    np.testing.assert_allclose(back.times, anim.times, atol=1e-5)
    assert out.read_bytes().split(b"\n")[3].endswith(b",0")


@pytest.mark.parametrize(
    "text, message",
    [
        (HEADER + b"\nnot-a-time,3,0.1,0.2,0.3\n", "bad timecode"),
        (HEADER + b"\n00:00:01:00.000,3,0.1,0.2\n", "fields"),
        (HEADER + b"\n00:00:01:00.000,3,0.1,abc,0.3\n", "not a number"),
        (b"Timecode,BlendshapeCount,HeadYaw\n00:00:01:00.000,1,0.1\n", "no blendshape"),
        (HEADER + b"\n", "no frames"),
    ],
)
def test_bad_files_raise_one_line(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_bytes(text)
    with pytest.raises(FacecleanError, match=message) as e:
        load(path)
    assert "\n" not in str(e.value)
