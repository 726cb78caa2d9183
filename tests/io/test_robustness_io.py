"""docs/ROBUSTNESS.md, files: every bad-input case answered by one line and exit 2, or by
its documented behaviour; inputs never modified; refused runs leave no file behind."""

from __future__ import annotations

import functools
import hashlib
import json
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.filters.base import check_finite
from faceclean.io import source, stream
from faceclean.resolve import resolve
from faceclean.settings import takes_dir

TAKES = takes_dir()
SMALL = TAKES / "jmtechart" / "MySlate_3_iPhone.csv" if TAKES else None  # 5.5 s, 60 fps
LOSS = TAKES / "alexdjulin" / "apfel.csv" if TAKES else None  # 35 tracking-loss rows
needs_takes = pytest.mark.skipif(TAKES is None, reason="../shared/data/arkit_takes is absent")
STREAMING = ["ema", "one-euro", "kalman"]
OFFLINE = ["gaussian", "savgol"]
LL_HEAD = b"Timecode,BlendshapeCount,EyeBlinkLeft,JawOpen,HeadYaw\n"


def _ll(*rows: str) -> bytes:
    return LL_HEAD + "".join(r + "\n" for r in rows).encode()


def _state(folder: Path) -> dict[str, str]:
    """name -> sha256 of every file under ``folder`` (temporaries included)."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _refused(capsys, argv: list[str], folder: Path, message: str) -> None:
    """The command exits 2 with one line naming ``message``, and ``folder`` is unchanged."""
    before = _state(folder)
    assert main(argv) == 2, argv
    err = capsys.readouterr().err
    assert err.startswith("faceclean: ") and err.count("\n") == 1, err
    assert message in err, err
    assert _state(folder) == before  # input untouched, no output, no temporary


# -- refused inputs ------------------------------------------------------------------------

BAD_FILES = {
    # case: (file name, bytes, words of the message)
    "empty csv": ("e.csv", b"", "not a Live Link Face CSV, a MediaPipe CSV"),
    "empty json": ("e.json", b"", "not valid JSON"),
    "empty npz": ("e.npz", b"", "not a readable npz"),
    "empty glb": ("e.glb", b"", "glTF"),
    "header only, live link": ("h.csv", LL_HEAD, "no frames"),
    "header only, plain": ("h.csv", b"time,jawOpen\n", "no frames"),
    "header only, json": (
        "h.json",
        b'{"format": "faceclean-animation/1", "channels": ["a"], "times": [], "values": []}',
        "no frames",
    ),
    "garbage csv": ("g.csv", bytes(range(256)) * 4, "not a Live Link Face CSV, a MediaPipe CSV"),
    "garbage json": ("g.json", b"\xff\xfe" + bytes(range(200)), "g.json: not"),
    "garbage npz": ("g.npz", b"PK\x03\x04" + bytes(range(200)), "not a readable npz"),
    "garbage glb": ("g.glb", b"glTF" + bytes(range(200)), "GLB"),
    "unknown extension": ("a.txt", b"time,jawOpen\n0,1\n", "unknown file type '.txt'"),
    "no extension": ("take", b"time,jawOpen\n0,1\n", "unknown file type '(none)'"),
    "foreign json": ("f.json", b'{"frames": [1, 2]}', "not a faceclean-animation/1 JSON"),
    "foreign zip as npz": ("z.npz", None, "not an npz archive (holds 'readme.txt')"),
    "pickle renamed npz": ("p.npz", pickle.dumps({"times": [0.0]}), "not a readable npz"),
    "text in a number, live link": (
        "t.csv",
        _ll("00:00:00:00.000,3,0.1,abc,0"),
        "a value is not a number",
    ),
    "text in a number, plain": ("t.csv", b"time,jawOpen\n0,0.5\n0.1,x\n", "row 2, field 2: 'x'"),
    "text as time, plain": ("t.csv", b"time,jawOpen\nnow,0.5\n", "not a number"),
    "bad timecode": ("t.csv", _ll("noon,3,0.1,0.2,0"), "line 2: bad timecode"),
    "ragged row, live link": ("r.csv", _ll("00:00:00:00.000,3,0.1,0.2"), "line 2: 4 fields"),
    "ragged row, plain": ("r.csv", b"time,jawOpen\n0,0.5\n0.1,0.5,9\n", "row 2 has 3 fields"),
    "nan time, plain": ("n.csv", b"time,jawOpen\nnan,0.5\n", "finite time"),
    "null time, json": (
        "n.json",
        b'{"format": "faceclean-animation/1", "channels": ["a"], "times": [null], "values": [[1]]}',
        "frame 0 has no finite time",
    ),
    "object in json values": (
        "o.json",
        b'{"format": "faceclean-animation/1", "channels": ["a"], "times": [0], '
        b'"values": [[{"x": 1}]]}',
        "not a readable json",
    ),
    "deeply nested json": ("d.json", b"[" * 100_000 + b"]" * 100_000, "nested too deep"),
    "time column only": ("c.csv", b"time\n0\n0.1\n", "no channels"),
    # a channel twice: clean kept both, info counted one, a glb kept one (fourth red team)
    "a channel twice, plain": (
        "d.csv",
        b"time,jawOpen,JawOpen\n0,0.1,0.2\n0.1,0.2,0.3\n",
        "channel 'jawOpen' is given twice",
    ),
    "a channel twice, json": (
        "d.json",
        b'{"format": "faceclean-animation/1", "channels": ["jawOpen", "jawOpen"], '
        b'"times": [0, 0.1], "values": [[0.1, 0.2], [0.2, 0.3]]}',
        "is given twice",
    ),
}


def _write_bad(folder: Path, name: str, data: bytes | None) -> Path:
    p = folder / name
    if data is None:  # a zip archive that is not our npz
        with zipfile.ZipFile(p, "w") as z:
            z.writestr("readme.txt", "not an animation")
    else:
        p.write_bytes(data)
    return p


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_bad_file_is_one_line_exit_2_nothing_written(tmp_path, capsys, case):
    name, data, message = BAD_FILES[case]
    src = _write_bad(tmp_path, name, data)
    with pytest.raises(FacecleanError) as e:
        io.load(src)
    assert "\n" not in str(e.value)
    for out in ("o.csv", "o.json"):
        argv = ["clean", str(src), "-o", str(tmp_path / out), "--method", "ema"]
        # -o naming the input itself: refused first as a raw take (issue 19), never written
        _refused(capsys, argv, tmp_path, "is the input" if out == name else message)
    _refused(capsys, ["convert", str(src), "-o", str(tmp_path / "o.npz")], tmp_path, message)
    _refused(capsys, ["info", str(src)], tmp_path, message)


def test_npz_with_object_arrays_is_refused_without_unpickling(tmp_path):
    p = tmp_path / "o.npz"
    names = np.array([object()], dtype=object)
    np.savez(p, times=np.zeros(1), values=np.zeros((1, 1)), names=names)
    with pytest.raises(FacecleanError, match="Object arrays cannot be loaded"):
        io.load(p)


def test_truncated_npz_is_refused(tmp_path):
    p = tmp_path / "t.npz"
    np.savez(p, times=np.arange(100.0), values=np.zeros((100, 2)), names=np.array(["a", "b"]))
    p.write_bytes(p.read_bytes()[:300])
    with pytest.raises(FacecleanError, match="not a readable npz"):
        io.load(p)


def _npz_bytes(**arrays) -> bytes:
    import io as stdio

    buf = stdio.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def test_npz_with_an_unsupported_compression_method_is_refused(tmp_path):
    # found by `faceclean fuzz --target npz`: zipfile raised NotImplementedError
    data = bytearray(_npz_bytes(times=np.zeros(2), values=np.zeros((2, 1)), names=np.array(["a"])))
    for sig, at in ((b"PK\x03\x04", 8), (b"PK\x01\x02", 10)):  # local and central headers
        i = data.find(sig)
        while i >= 0:
            data[i + at : i + at + 2] = (1).to_bytes(2, "little")  # method 1: "shrunk"
            i = data.find(sig, i + 1)
    p = tmp_path / "m.npz"
    p.write_bytes(bytes(data))
    with pytest.raises(FacecleanError, match="not a readable npz file"):
        io.load(p)


def test_npz_size_limits_refuse_big_files_and_zip_bombs(tmp_path):
    from faceclean.io.npz_safe import MiB, load_arrays

    p = tmp_path / "bomb.npz"
    np.savez_compressed(p, zeros=np.zeros(3 * MiB // 8))  # 3 MiB of zeros in a few KiB
    assert p.stat().st_size < MiB
    with pytest.raises(FacecleanError, match="unpacks to 3.0 MiB, over the 2.0 MiB limit"):
        load_arrays(p, max_bytes=2 * MiB)
    with pytest.raises(FacecleanError, match="over the 1000 bytes limit"):
        load_arrays(p, max_bytes=1000)
    assert load_arrays(p, max_bytes=4 * MiB)["zeros"].shape == (3 * MiB // 8,)


def test_missing_input_and_folder_input(tmp_path, capsys):
    _refused(capsys, ["info", str(tmp_path / "none.csv")], tmp_path, "no such file")
    (tmp_path / "dir.csv").mkdir()
    _refused(capsys, ["info", str(tmp_path / "dir.csv")], tmp_path, "is a folder")


# -- outputs -------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["one-euro", "gaussian"])  # streamed and whole
def test_output_in_a_missing_folder_is_refused(tmp_path, capsys, method):
    src = tmp_path / "a.csv"
    src.write_bytes(b"time,jawOpen\n0,0.5\n0.1,0.6\n")
    out = tmp_path / "missing" / "o.csv"
    argv = ["clean", str(src), "-o", str(out), "--method", method]
    _refused(capsys, argv, tmp_path, "output folder does not exist")
    assert not out.parent.exists()


@pytest.mark.parametrize("method", ["one-euro", "gaussian"])
def test_output_equal_to_input_is_replaced_whole(tmp_path, capsys, method):
    src = tmp_path / "a.csv"
    src.write_bytes(b"time,jawOpen\n0,0.5\n0.1,0.9\n0.2,0.1\n")
    expect = resolve(method).build(("jawOpen",)).clean(io.load(src))
    assert main(["clean", str(src), "-o", str(src), "--method", method, "--in-place"]) == 0
    got = io.load(src)
    assert np.array_equal(got.values, expect.values) and np.array_equal(got.times, expect.times)
    assert [p.name for p in tmp_path.iterdir()] == ["a.csv"]  # no temporary left


def test_refused_in_place_run_keeps_the_input(tmp_path, capsys):
    # the bad row comes late: the stream has already written blocks to its temporary
    src = tmp_path / "a.csv"
    rows = b"".join(b"%d,0.5\n" % i for i in range(3 * stream.BLOCK))
    src.write_bytes(b"time,jawOpen\n" + rows + b"x,0.5\n")
    argv = ["clean", str(src), "-o", str(src), "--method", "one-euro", "--in-place"]
    _refused(capsys, argv, tmp_path, "not a number")


# -- values and channels -------------------------------------------------------------------


@pytest.mark.parametrize("method", STREAMING + OFFLINE)
def test_nan_inf_and_absurd_values_never_reach_the_output(method):
    t = np.arange(40) / 60.0
    x = 0.5 + 0.2 * np.sin(t * 7)[:, None] * np.ones((1, 3))  # (40, 3)
    x[5, 0], x[9, 1], x[12, 2], x[20] = np.nan, np.inf, -1e300, np.nan  # 20: tracking loss
    x[30, 0] = 1e7
    anim = Animation(t, x, ("jawOpen", "eyeBlinkLeft", "mouthClose"))
    out = resolve(method).build(anim.names).clean(anim).values
    assert np.isnan(out[20]).all()  # a missing frame stays missing
    rest = np.delete(out, 20, axis=0)
    assert np.isfinite(rest).all() and rest.min() > 0.2 and rest.max() < 0.8


def test_nan_and_inf_cells_hold_the_last_output_in_live_link(tmp_path, capsys):
    src = tmp_path / "a.csv"
    src.write_bytes(
        _ll(
            "00:00:00:00.000,3,0.1000,0.2000,0.5",
            "00:00:00:01.000,3,nan,0.3000,0.5",
            "00:00:00:02.000,3,0.9000,inf,0.5",
            "00:00:00:03.000,0",
            "00:00:00:04.000,3,0.1000,0.2000,0.5",
        )
    )
    out = tmp_path / "o.csv"
    assert main(["clean", str(src), "-o", str(out), "--method", "ema"]) == 0
    cells = [line.split(b",") for line in out.read_bytes().split(b"\n")]
    assert cells[2][2] == cells[1][2] == b"0.1000"  # NaN: the channel's last output
    assert cells[3][3] == cells[2][3]  # inf: the same rule, in the source's format
    assert b"".join(cells[4]) == b"00:00:00:03.0000"  # tracking loss written back as it was
    assert all(c[-1] == b"0.5" for c in cells[1:4] + cells[5:6])  # angles as text


def test_missing_and_unknown_channels_pass_through(tmp_path, capsys):
    # Live Link: an unknown column is passthrough text; channels the file lacks stay absent
    src = tmp_path / "a.csv"
    head = b"Timecode,BlendshapeCount,JawOpen,MyRigKnob,HeadYaw\n"
    body = b"".join(b"00:00:00:%02d.000,3,0.%d000,7.25,0.1\n" % (i, i % 10) for i in range(30))
    src.write_bytes(head + body)
    out = tmp_path / "o.csv"
    assert main(["clean", str(src), "-o", str(out), "--method", "one-euro"]) == 0
    for a, b in zip(src.read_bytes().split(b"\n"), out.read_bytes().split(b"\n"), strict=True):
        fa, fb = a.split(b","), b.split(b",")
        assert fa[:2] == fb[:2] and fa[3:] == fb[3:]  # timecode, count, knob, yaw as text
    anim = io.load(out)
    assert anim.names == ("JawOpen",) and anim.meta["pose_names"] == ("MyRigKnob", "HeadYaw")
    # plain CSV: a non-ARKit column is kept, in place, as a channel
    plain = tmp_path / "p.csv"
    plain.write_bytes(b"time,myThing,jawOpen\n0,7,0.1\n0.1,7,0.2\n")
    assert main(["clean", str(plain), "-o", str(tmp_path / "q.json"), "--method", "ema"]) == 0
    got = io.load(tmp_path / "q.json")
    assert got.names == ("myThing", "jawOpen") and np.allclose(got.values[:, 0], 7.0)


def test_json_and_npz_carry_their_passthrough_through_clean(tmp_path, capsys):
    pose = np.linspace(0, 1, 20)[:, None] * np.array([[1.0, -2.0]])
    anim = Animation(np.arange(20) / 30, np.full((20, 2), 0.25), ("jawOpen", "custom"))
    anim.meta.update(pose=pose, pose_names=("HeadYaw", "Extra"), timecode_start=53882.5)
    for ext in ("json", "npz"):
        src, out = tmp_path / f"a.{ext}", tmp_path / f"o.{ext}"
        io.save(anim, src)
        assert main(["clean", str(src), "-o", str(out), "--method", "kalman"]) == 0
        got = io.load(out)
        assert np.array_equal(got.meta["pose"][:, 1], pose[:, 1])  # passthrough
        assert 0 < np.abs(got.meta["pose"][:, 0] - pose[:, 0]).max() < 0.01  # an angle: cleaned
        assert got.meta["pose_names"] == ("HeadYaw", "Extra")
        assert got.meta["timecode_start"] == 53882.5 and got.names == anim.names


# -- time ----------------------------------------------------------------------------------


@pytest.mark.parametrize("method", STREAMING + OFFLINE)
def test_repeated_and_backwards_times_hold_the_last_output(method):
    t = np.array([0.0, 1, 2, 2, 3, 1.5, 4, 5]) / 60  # a duplicate, then a step back
    x = np.linspace(0.1, 0.8, len(t))[:, None] * np.ones((1, 2))
    out = (
        resolve(method)
        .build(("jawOpen", "eyeBlinkLeft"))
        .clean(Animation(t, x, ("jawOpen", "eyeBlinkLeft")))
        .values
    )
    assert np.array_equal(out[3], out[2]) and np.array_equal(out[5], out[4])
    assert np.isfinite(out).all()


@pytest.mark.parametrize("method", STREAMING + OFFLINE)
def test_one_hour_gap_restarts_without_smearing(method):
    t = np.concatenate([np.arange(30) / 60, 3600 + np.arange(30) / 60])  # s
    x = np.concatenate([np.full(30, 0.1), np.full(30, 0.9)])[:, None]
    out = resolve(method).build(("jawOpen",)).clean(Animation(t, x, ("jawOpen",))).values
    assert np.allclose(out[:30], 0.1) and np.allclose(out[30:], 0.9)  # no jump across


@pytest.mark.parametrize("method", STREAMING + OFFLINE)
def test_single_frame_comes_back_unchanged(tmp_path, capsys, method):
    src = tmp_path / "a.csv"
    src.write_bytes(b"time,jawOpen,eyeBlinkLeft\n12.5,0.25,0.75\n")
    out = tmp_path / "o.csv"
    assert main(["clean", str(src), "-o", str(out), "--method", method]) == 0
    assert out.read_bytes() == src.read_bytes()


# -- the streaming path --------------------------------------------------------------------


def _in_memory(src: Path, dst: Path, method: str) -> None:
    anim = io.load(src)
    io.save(resolve(method).build(anim.names).clean(anim), dst)


def _streamed(src: Path, dst: Path, method: str) -> tuple[int, int]:
    fmt = io.detect(src)
    cleaner = resolve(method).build(stream.channel_names(src, fmt))
    assert cleaner.stepwise and stream.can_stream(fmt, fmt)
    cleaner.reset()
    check = functools.partial(check_finite, name=cleaner.name)
    return stream.clean_file(src, dst, cleaner.step, fmt, check=check)


def _edge_files() -> dict[str, bytes]:
    rng = np.random.default_rng(5)
    rows = [
        f"23:59:59:{i % 60:02d}.{i % 1000:03d},3,{rng.random():.6f},{rng.random():.6f},0.1"
        for i in range(40)
    ]
    rows[7] = "23:59:59:07.000,0"  # tracking loss
    rows[20] = "00:00:00:00.000,3,0.5,0.5,0.1"  # past midnight
    ll = "\n".join(rows)
    plain = "\n".join(f"{i / 60!r},{rng.random()!r},,{rng.random()!r}" for i in range(40))
    return {
        "ll.csv": LL_HEAD + ll.encode() + b"\n",
        "ll_crlf.csv": (LL_HEAD.decode() + ll).replace("\n", "\r\n").encode(),  # no final EOL
        "ll_cr.csv": (LL_HEAD.decode() + ll + "\n").replace("\n", "\r").encode(),
        "ll_bom_blank.csv": b"\xef\xbb\xbf" + LL_HEAD + ll.replace("\n", "\n\n", 3).encode(),
        "plain.csv": b"time,jawOpen,eyeBlinkLeft,custom\n" + plain.encode() + b"\n",
        "plain_crlf.csv": b"\xef\xbb\xbftime,a,b,c\r\n" + plain.replace("\n", "\r\n\r\n").encode(),
    }


@pytest.mark.parametrize("method", STREAMING)
def test_streaming_equals_in_memory_byte_for_byte(tmp_path, monkeypatch, method):
    monkeypatch.setattr(stream, "BLOCK", 7)  # many block boundaries
    monkeypatch.setattr(source, "CHUNK", 61)  # reads that split lines and "\r\n"
    files = {n: tmp_path / n for n in _edge_files()}
    for name, data in _edge_files().items():
        files[name].write_bytes(data)
    if SMALL is not None:
        files["take.csv"] = SMALL
    for name, src in files.items():
        a, b = tmp_path / f"mem_{name}", tmp_path / f"str_{name}"
        _in_memory(src, a, method)
        frames, missing = _streamed(src, b, method)
        assert a.read_bytes() == b.read_bytes(), name
        anim = io.load(src)
        assert (frames, missing) == (anim.n_frames, int((~anim.valid).sum())), name


def test_a_plain_csvs_head_angles_are_angles_streamed_or_not(tmp_path, monkeypatch):
    """Angle columns (Live Link names, any case) of a plain CSV: read as the take's head
    pose, not as weights; cleaned by the rotation filter; written after the channels; the
    stream's bytes equal the in-memory path's, tracking loss included."""
    from faceclean.filters import rotation

    monkeypatch.setattr(stream, "BLOCK", 7)
    rng = np.random.default_rng(2)
    rows = []
    for i in range(60):
        yaw = float(0.6 * np.sin(i / 9) + rng.normal(0, 0.01))
        jaw = "" if i == 17 else repr(float(rng.random()))  # frame 17: tracking loss
        blink = "" if i == 17 else repr(float(rng.random()))
        rows.append(f"{i / 60!r},{jaw},{yaw!r},{blink},{-0.5 * yaw!r}")
    src = tmp_path / "take.csv"
    src.write_text("time,jawOpen,HeadYaw,eyeBlinkLeft,headpitch\n" + "\n".join(rows) + "\n")
    anim = io.load(src)
    assert anim.names == ("jawOpen", "eyeBlinkLeft")
    assert anim.meta["pose_names"] == ["HeadYaw", "HeadPitch"]
    assert stream.channel_names(src, "csv") == anim.names
    assert stream.angle_names(src, "csv") == ("HeadYaw", "HeadPitch")
    choice = resolve("one-euro")
    mem, streamed = tmp_path / "mem.csv", tmp_path / "str.csv"
    io.save(rotation.clean_pose(choice.build(anim.names).clean(anim), choice.build_pose), mem)
    cleaner, pose = choice.build(anim.names), choice.build_pose(("HeadYaw", "HeadPitch"))
    cleaner.reset()
    pose.reset()
    stream.clean_file(src, streamed, cleaner.step, "csv", pose_step=pose.step)
    assert mem.read_bytes() == streamed.read_bytes()
    back = io.load(mem)
    assert back.names == anim.names and back.meta["pose_names"] == ["HeadYaw", "HeadPitch"]
    assert back.meta["pose"][17, 0] == anim.meta["pose"][17, 0]  # a lost frame's angle kept
    moved = np.abs(back.meta["pose"] - anim.meta["pose"]).max()
    assert 0 < moved < 0.1  # cleaned as angles, not clamped to [0, 1] as weights would be
    assert (back.meta["pose"][:, 1] < 0).any()


def test_iter_lines_matches_splitlines():
    import io as stdio

    data = b"a\r\nb\rc\n\nd\r\r\ne"
    for chunk in (1, 2, 3, 5, 100):
        assert list(source.iter_lines(stdio.BytesIO(data), chunk)) == data.splitlines(True)


def test_clean_streams_only_when_it_can():
    one_euro, gaussian = resolve("one-euro").build(), resolve("gaussian").build()
    assert stream.can_stream("livelink", "livelink") and one_euro.stepwise
    assert stream.can_stream("csv", "csv")
    assert not stream.can_stream("livelink", "json")  # another format: whole
    assert not stream.can_stream("json", "json")
    assert not gaussian.stepwise  # offline: whole


@needs_takes
def test_tracking_loss_rows_survive_the_stream(tmp_path, capsys):
    out = tmp_path / "o.csv"
    assert main(["clean", str(LOSS), "-o", str(out), "--method", "one-euro"]) == 0
    assert "(35 missing)" in capsys.readouterr().out
    src_lines, out_lines = LOSS.read_bytes().split(b"\n"), out.read_bytes().split(b"\n")
    lost = [k for k, line in enumerate(src_lines) if line.count(b",") == 1]
    assert len(lost) == 35 and all(out_lines[k] == src_lines[k] for k in lost)


@needs_takes
def test_real_take_is_never_modified(tmp_path, capsys):
    take = tmp_path / "take.csv"
    shutil.copyfile(SMALL, take)
    digest = hashlib.sha256(take.read_bytes()).hexdigest()
    for method in ("one-euro", "gaussian"):
        for ext in ("csv", "json", "npz"):
            argv = ["clean", str(take), "-o", str(tmp_path / f"{method}.{ext}")]
            assert main([*argv, "--method", method]) == 0
    assert main(["convert", str(take), "-o", str(tmp_path / "c.json")]) == 0
    assert main(["info", str(take)]) == 0
    assert hashlib.sha256(take.read_bytes()).hexdigest() == digest
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert json.loads((tmp_path / "c.json").read_text())["format"] == "faceclean-animation/1"


# -- model and preset files: no pickle, size- and shape-checked ----------------------------


def _model_arrays() -> dict[str, np.ndarray]:
    from faceclean.learned.checkpoint import LSTMWeights

    return LSTMWeights.random(("jawOpen", "eyeBlinkLeft"), hidden=8, layers=2).to_arrays()


def _bad_models(folder: Path) -> dict[str, tuple[Path, str]]:
    """name -> (model file, words of the refusal)."""
    out: dict[str, tuple[Path, str]] = {}

    def put(name: str, message: str, data: bytes | None = None, **arrays) -> None:
        p = folder / f"{name}.npz"
        if data is not None:
            p.write_bytes(data)
        else:
            np.savez(p, **arrays)
        out[name] = (p, message)

    good = _model_arrays()
    put("good", "", **good)
    put("wrong_shape", "lstm.0.w_hh has shape", **{**good, "lstm.0.w_hh": np.zeros((32, 7))})
    missing = {k: v for k, v in good.items() if k != "head.b"}
    put("missing_key", "missing array 'head.b'", **missing)
    put("no_config", "no readable 'config'", **{k: v for k, v in good.items() if k != "config"})
    foreign = {**good, "config": np.array(json.dumps({"format": "someone-else/3"}))}
    put("foreign_config", "not a faceclean-lstm/1 checkpoint", **foreign)
    obj = {**good, "feat_mean": np.array([object()], dtype=object)}
    put("object_array", "Object arrays cannot be loaded", **obj)
    put("pickle", "not a zip archive", data=pickle.dumps(good))
    put("truncated", "not a readable model .npz", data=_npz_bytes(**good)[:500])
    with zipfile.ZipFile(folder / "zip.npz", "w") as z:
        z.writestr("weights.bin", b"\0" * 64)
    out["zip"] = (folder / "zip.npz", "not an npz archive")
    big = folder / "big.npz"
    with open(big, "wb") as f:  # sparse: 65 MiB on paper, nothing on disk
        f.write(b"PK\x03\x04")
        f.truncate(65 << 20)
    out["too_big"] = (big, "65.0 MiB, over the 64.0 MiB limit")
    return out


def test_model_files_are_checked_before_use(tmp_path):
    from faceclean.learned.checkpoint import LSTMWeights

    for name, (path, message) in _bad_models(tmp_path).items():
        before = hashlib.sha256(path.read_bytes()).hexdigest()
        if name == "good":
            assert LSTMWeights.load(path).hidden == 8
            continue
        with pytest.raises(FacecleanError, match=message) as e:
            LSTMWeights.load(path)
        assert "\n" not in str(e.value), name
        assert hashlib.sha256(path.read_bytes()).hexdigest() == before


def test_bad_model_through_the_cli_is_one_line(tmp_path, capsys):
    work, store = tmp_path / "work", tmp_path / "models"
    work.mkdir(), store.mkdir()
    src = work / "a.csv"
    src.write_bytes(b"time,jawOpen\n0,0.5\n0.1,0.6\n")
    models = _bad_models(store)
    for method, key in (("lstm", "model"), ("fc", "model"), ("gbt", "model")):
        for name in ("pickle", "object_array", "truncated", "too_big"):
            model = models[name][0]
            argv = ["clean", str(src), "-o", str(work / "o.csv"), "--method", method]
            _refused(capsys, [*argv, "--set", f"{key}={model}"], work, model.name)


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"format": "faceclean-preset/1", "method": "ema", "params": {"tau": "fast"}}, "finite"),
        ({"format": "faceclean-preset/1", "method": "ema", "params": [1, 2]}, "an object"),
        ({"format": "faceclean-preset/1", "method": "ema", "params": {"tau": True}}, "finite"),
        ({"format": "faceclean-preset/1", "method": 3}, "unknown method"),
        ({"format": "faceclean-preset/1", "method": "ema", "groups": {"ears": {}}}, "group"),
        ({"format": "faceclean-preset/1", "method": "ema", "extra": 1}, "unknown key"),
        ({"format": "other/1", "method": "ema"}, "format must be"),
        ([1, 2, 3], "a JSON object"),
        ("[" * 50_000, "not valid JSON"),
        (b"\x80\x04\x95 pickle", "not valid JSON"),
    ],
)
def test_malformed_presets_are_one_line(tmp_path, capsys, doc, message):
    p = tmp_path / "p.json"
    if isinstance(doc, bytes):
        p.write_bytes(doc)
    else:
        p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    src = tmp_path / "a.csv"
    src.write_bytes(b"time,jawOpen\n0,0.5\n0.1,0.6\n")
    argv = ["clean", str(src), "-o", str(tmp_path / "o.csv"), "--preset", str(p)]
    _refused(capsys, argv, tmp_path, message)


@pytest.mark.parametrize("when", ["after the file is created", "while writing"])
def test_an_interrupt_at_any_point_of_a_write_leaves_no_file(tmp_path, monkeypatch, when):
    """A Ctrl-C or SIGTERM (the CLI raises on both) handled at the first instant after the
    temporary file exists leaves nothing behind (tempfile.mkstemp had a window there), and
    an existing output stays as it was."""
    from faceclean.io import atomic

    out = tmp_path / "out.csv"
    out.write_text("before")
    real_open = atomic.os.open

    def created_then_interrupted(path, flags, mode=0o777):
        real_open(path, flags, mode)  # the file now exists; the handler runs before return
        raise KeyboardInterrupt

    if when == "after the file is created":
        monkeypatch.setattr(atomic.os, "open", created_then_interrupted)
    with pytest.raises(KeyboardInterrupt), atomic.atomic_open(out, "w") as f:
        f.write("half")
        raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]
    assert out.read_text() == "before"


def _small_take(path: Path) -> bytes:
    path.write_text("time,jawOpen\n0,0.1\n0.1,0.2\n0.2,0.3\n")
    return path.read_bytes()


def test_a_read_only_output_is_not_replaced(tmp_path, capsys):
    # red team: a write is a rename, so a 0444 file was replaced without a word
    src, out = tmp_path / "in.csv", tmp_path / "keep.csv"
    _small_take(src)
    out.write_text("mine\n")
    out.chmod(0o444)
    for args in (["convert", str(src), "-o", str(out)],
                 ["clean", str(src), "-o", str(out), "--method", "ema"]):  # fmt: skip
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err == f"faceclean: {out} is read-only: nothing replaces it unasked (make it " \
                      "writable, or name another file)"  # fmt: skip
        assert out.read_text() == "mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.csv", "keep.csv"]


@pytest.mark.parametrize("where", ["dangling", "proc"])
def test_an_output_that_cannot_be_written_is_refused_before_the_work(tmp_path, capsys, where):
    # red team: relay --record through a dangling link, or into /proc, took a whole session
    # and then lost it at the end with a raw errno message
    out = tmp_path / "rec.csv"
    if where == "dangling":
        out.symlink_to(tmp_path / "gone" / "x.csv")
    else:
        out = Path("/proc/self/x.csv")
    args = ["relay", "--listen", "vmc://127.0.0.1:0", "--send", "vmc://127.0.0.1:9"]
    assert main([*args, "--record", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("faceclean: --record: ")
    assert ("output folder does not exist" in err) if where == "dangling" else (
        "cannot write in /proc/" in err)  # fmt: skip
    if where == "dangling":
        assert not (tmp_path / "gone").exists()


# -- issue 37: nothing non-finite written; kernel files are not files -------------------------


def _ll_angles(head_yaw: str, head_pitch: str) -> bytes:
    head = b"Timecode,BlendshapeCount,EyeBlinkLeft,JawOpen,HeadYaw,HeadPitch\n"
    rows = [f"00:00:00:{i:02d}.000,2,0.1,0.2,{head_yaw if i == 2 else 0.1},"
            f"{head_pitch if i == 3 else 0.0}" for i in range(6)]  # fmt: skip
    return head + "\n".join(rows).encode() + b"\n"


def _strict(text: str):
    def refuse(name):
        raise ValueError(f"{name} is not JSON")

    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize(("yaw", "pitch"), [("1e308", "-1e308"), ("1.7e308", "-0.5")])
def test_huge_finite_angles_convert_to_strict_json(tmp_path, capsys, yaw, pitch):
    src = tmp_path / "take.csv"
    src.write_bytes(_ll_angles(yaw, pitch))
    out = tmp_path / "take.json"
    assert main(["convert", str(src), "-o", str(out)]) == 0
    doc = _strict(out.read_text())  # a strict reader reads it: no Infinity token
    pose = np.array(doc["pose"], dtype=np.float64)
    assert np.isfinite(pose).all() and pose[2, 0] == float(yaw)
    back = io.load(out)
    np.testing.assert_array_equal(back.meta["pose"], pose)


@pytest.mark.parametrize(("yaw", "pitch"), [("inf", "0.1"), ("0.1", "-inf"), ("1e309", "0.2")])
def test_infinite_angles_are_refused_by_json_in_one_line(tmp_path, capsys, yaw, pitch):
    src = tmp_path / "take.csv"
    src.write_bytes(_ll_angles(yaw, pitch))
    out = tmp_path / "take.json"
    assert main(["convert", str(src), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "JSON cannot hold infinite values" in err, err
    assert "HeadYaw" in err or "HeadPitch" in err
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["take.csv"]


@pytest.mark.parametrize("option", ["--calibration", "--preset", "--model"])
def test_kernel_files_are_refused_as_the_special_files_they_are(tmp_path, capsys, option):
    """/proc/self/mem stats as a regular file of 0 bytes and fails mid-read (EIO)."""
    src = tmp_path / "take.csv"
    src.write_bytes(_ll_angles("0.1", "0.1"))
    out = tmp_path / "o.csv"
    code = main(["clean", str(src), "-o", str(out), option, "/proc/self/mem"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "internal error" not in err and "Errno" not in err
    assert not out.exists()
    with pytest.raises(FacecleanError, match="kernel file"):
        io.load("/proc/self/mem")
