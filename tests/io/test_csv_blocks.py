"""CSV on the whole-take path (issue 38): a streamed clean whose blocks go through
``Stepper.steps`` (runs of frames compiled) writes the bytes the in-memory path writes, and
the plain CSV reader and writer, a block at a time, give what they gave whole."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.datasets.performer import perform
from faceclean.errors import FacecleanError
from faceclean.filters import compiled
from faceclean.filters.base import check_finite
from faceclean.io import plain_csv, stream
from faceclean.resolve import resolve

# the shipped default (adaptive, a StreamCleaner), the classical ones, and one whose own
# step decides (the MediaPipe map: Stepper.steps, frame by frame; the LSTM never streams)
METHODS = [None, "ema", "one-euro", "kalman", "mediapipe"]
OWN_STEP = ("mediapipe",)  # its whole-take loop agrees with stepping to 1e-12


def _take(tmp_path, fmt: str):
    anim = perform(8.0, 3, fps=60.0)
    values, times = anim.values.copy(), anim.times.copy()
    values[100:104] = np.nan  # tracking loss
    values[200, 3] = np.inf if fmt == "csv" else 0.123456789  # a bad cell: the last output held
    times[400:] += 2.0  # a pause longer than max_gap: the state restarts
    path = tmp_path / f"take_{fmt}.csv"
    io.save(Animation(times, values, anim.names, anim.meta), path, fmt=fmt)
    if fmt == "livelink":  # the writer refuses inf: the cell as a hostile file spells it
        text = path.read_bytes()
        assert text.count(b",0.1234567890,") == 1
        path.write_bytes(text.replace(b",0.1234567890,", b",inf,"))
    return path


def _choice(method: str | None):
    if method == "mediapipe":  # the shipped MediaPipe cleaner, as --tracker mediapipe
        from faceclean.resolve import tracker_words

        return resolve(tracker_words("mediapipe"))
    return resolve(method)


@pytest.fixture
def compiled_on():
    pytest.importorskip("numba")
    was = compiled.enabled()
    assert compiled.enable(warm=False)
    yield
    if not was:
        compiled.disable()


@pytest.mark.parametrize("fmt", ["csv", "livelink"])
@pytest.mark.parametrize("method", METHODS)
def test_streamed_blocks_through_steps_equal_the_whole_take(
    tmp_path, monkeypatch, compiled_on, method, fmt
):
    monkeypatch.setattr(stream, "BLOCK", 97)  # many block boundaries, runs cut across them
    src = _take(tmp_path, fmt)
    choice = _choice(method)
    anim = io.load(src)
    mem, streamed = tmp_path / "mem.csv", tmp_path / "str.csv"
    io.save(choice.build(anim.names).clean(anim), mem, fmt=fmt)
    cleaner = choice.build(stream.channel_names(src, fmt))
    assert cleaner.stepwise
    cleaner.reset()
    check = functools.partial(check_finite, name=cleaner.name)
    frames, _ = stream.clean_file(src, streamed, cleaner.step, fmt, check=check,
                                  steps=cleaner.steps)  # fmt: skip
    assert frames == anim.n_frames
    if method in OWN_STEP:  # stepped as before; the whole take's own loop within 1e-12
        a, b = io.load(mem), io.load(streamed)
        np.testing.assert_allclose(b.values, a.values, rtol=0, atol=1e-9)
        assert np.array_equal(np.isnan(a.values), np.isnan(b.values))
    else:
        assert mem.read_bytes() == streamed.read_bytes()


def test_steps_is_step_frame_by_frame_for_every_stream_cleaner(compiled_on):
    anim = perform(3.0, 4, fps=60.0)
    x, t = anim.values.copy(), anim.times.copy()
    x[50, :] = np.nan  # a missing cell row goes to step's rules, not to the run
    x[60, 2] = 1e9  # absurd
    t[90:] += 1.5
    for method in ("ema", "one-euro", "kalman", None):
        a, b = resolve(method).build(anim.names), resolve(method).build(anim.names)
        a.reset()
        b.reset()
        want = np.array([a.step(x[k], t[k]) for k in range(len(x))])
        got = np.concatenate([b.steps(t[k : k + 37], x[k : k + 37]) for k in range(0, len(x), 37)])
        np.testing.assert_array_equal(got, want)


def test_the_plain_reader_and_writer_in_blocks_are_the_whole_file(tmp_path, monkeypatch):
    text = (
        b"\xef\xbb\xbftime,jawOpen,HeadYaw,custom\r\n"
        + b"".join(
            f"{k / 60!r},{'' if k % 7 == 3 else repr(k / 97)},{0.01 * k!r},{k % 5!r}\r\n".encode()
            + (b"\r\n" if k % 11 == 0 else b"")  # blank lines
            for k in range(50)
        )
        + b"0.9,,0.1,"  # the last row: no line ending, empty cells
    )
    src = tmp_path / "take.csv"
    src.write_bytes(text)
    whole = io.load(src)
    first = tmp_path / "whole.csv"
    io.save(whole, first)
    monkeypatch.setattr(plain_csv, "BLOCK", 3)
    blocks = io.load(src)
    np.testing.assert_array_equal(blocks.times, whole.times)
    np.testing.assert_array_equal(blocks.values, whole.values)
    np.testing.assert_array_equal(blocks.meta["pose"], whole.meta["pose"])
    assert blocks.names == whole.names == ("jawOpen", "custom") and blocks.n_frames == 51
    again = tmp_path / "blocks.csv"
    io.save(blocks, again)
    assert again.read_bytes() == first.read_bytes()
    bad = tmp_path / "bad.csv"
    bad.write_bytes(b"time,a\n" + b"".join(f"{k},0.5\n".encode() for k in range(7)) + b"8,x\n")
    with pytest.raises(FacecleanError, match="row 8, field 2: 'x' is not a number") as e:
        io.load(bad)  # (numpy's own words named np.bytes_, not the cell)
    assert "np.bytes" not in str(e.value)
    short = tmp_path / "short.csv"
    short.write_bytes(b"time,a,b\n0,1,2\n1,2,3\n2,3,4\n3,4\n")
    with pytest.raises(FacecleanError, match="row 4 has 2 fields, the header has 3"):
        io.load(short)
