"""Issue 14, classes 2-8 through the command line: every example of the issue, plus the
cases around it. Each one is a one-line refusal (exit 2) or a right answer; never an
internal error, a replaced FIFO or device, an overwritten input or a file of NaN.
"""

from __future__ import annotations

import base64
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO, gltf_doc

from faceclean import filters, io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.cli import main


def one_line(capsys, *want: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("faceclean: "), err
    assert "internal error" not in err[0] and "Warning" not in err[0], err[0]
    for w in want:
        assert w in err[0], err[0]
    return err[0]


@pytest.fixture
def take(tmp_path) -> Path:
    t = np.arange(120) / 60.0
    x = 0.5 + 0.3 * np.sin(2 * np.pi * t[:, None] + np.arange(52))
    p = tmp_path / "take.csv"
    io.save(Animation(t, x, ARKIT52, {"format": "csv"}), p)
    return p


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


# -- class 2: a file can read other files ---------------------------------------------------


def gltf_with_uri(folder: Path, uri: str) -> Path:
    """A .gltf whose one buffer (4 float32 times, 4 weights) lives at ``uri``."""
    doc, data = gltf_doc(uri)
    p = folder / "scene.gltf"
    p.write_text(json.dumps(doc))
    return p, data


@pytest.mark.parametrize("uri", ["../secret.bin", "sub/../../secret.bin", "%2e%2e/secret.bin"])
def test_gltf_buffer_uri_cannot_climb_out_of_its_folder(tmp_path, uri, capsys):
    # today: a URI climbing out of its folder got that file's bytes copied into the output
    scene = tmp_path / "scene"
    (scene / "sub").mkdir(parents=True)
    src, data = gltf_with_uri(scene, uri)
    (tmp_path / "secret.bin").write_bytes(data)
    assert main(["convert", str(src), "-o", str(tmp_path / "out.glb")]) == 2
    one_line(capsys, "leaves the file's folder")
    assert not (tmp_path / "out.glb").exists()


def test_gltf_buffer_symlink_out_of_its_folder_is_refused(tmp_path, capsys):
    scene = tmp_path / "scene"
    scene.mkdir()
    src, data = gltf_with_uri(scene, "buf.bin")
    (tmp_path / "secret.bin").write_bytes(data)
    (scene / "buf.bin").symlink_to(tmp_path / "secret.bin")
    assert main(["info", str(src)]) == 2
    one_line(capsys, "leaves the file's folder")


def test_gltf_buffer_beside_it_and_bounded_data_uri_are_read(tmp_path):
    src, data = gltf_with_uri(tmp_path, "buf.bin")
    (tmp_path / "buf.bin").write_bytes(data)
    assert io.load(src).values[:, 0].tolist() == [0.5] * 4
    src, _ = gltf_with_uri(
        tmp_path, "data:application/octet-stream;base64," + base64.b64encode(data).decode()
    )
    assert io.load(src).n_frames == 4


@pytest.mark.parametrize(
    "uri", ["/etc/passwd", "file:///etc/passwd", "data:text/plain,abc", "data:;base64,@@@@"]
)
def test_gltf_absolute_scheme_and_bad_data_uris_are_refused(tmp_path, uri, capsys):
    src, _ = gltf_with_uri(tmp_path, uri)
    assert main(["info", str(src)]) == 2
    one_line(capsys)


# -- class 3: an output path can destroy what it names --------------------------------------


def test_output_naming_a_fifo_is_refused_and_the_fifo_stays(tmp_path, take, capsys):
    # today: -o FIFO replaced the FIFO with a regular file
    fifo = tmp_path / "out.csv"
    os.mkfifo(fifo)
    assert main(["clean", str(take), "-o", str(fifo), "--method", "ema"]) == 2
    one_line(capsys, "a FIFO")
    assert fifo.is_fifo()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_output_through_a_symlink_to_a_device_is_refused(tmp_path, take, capsys):
    # today (as root): -o /dev/null replaced the system's /dev/null; a link to it is the same
    link = tmp_path / "null.csv"
    link.symlink_to("/dev/null")
    assert main(["synth", "-o", str(link), "--seconds", "1"]) == 2
    one_line(capsys, "character device")
    assert link.is_symlink() and Path("/dev/null").is_char_device()


def test_output_through_a_symlink_to_a_file_writes_the_file(tmp_path, take):
    real = tmp_path / "real.csv"
    real.write_bytes(b"old")
    link = tmp_path / "link.csv"
    link.symlink_to(real)
    assert main(["clean", str(take), "-o", str(link), "--method", "ema"]) == 0
    assert link.is_symlink() and io.load(real).n_frames == 120


def test_tune_output_naming_the_truth_is_refused(tmp_path, take, capsys):
    # today: tune -o the truth file overwrote it with the preset
    truth = tmp_path / "truth.json"
    main(["convert", str(take), "-o", str(truth)])
    capsys.readouterr()
    before = snapshot(tmp_path)
    assert (
        main(["tune", str(take), "--truth", str(truth), "--method", "ema", "-o", str(truth)]) == 2
    )
    one_line(capsys, "a file this command reads")
    assert snapshot(tmp_path) == before


def test_corrupt_truth_out_naming_the_input_is_refused(tmp_path, take, capsys):
    # today: corrupt --truth-out IN overwrote the clean input
    before = snapshot(tmp_path)
    args = ["corrupt", str(take), "-o", str(tmp_path / "noisy.csv"), "--seed", "1"]
    assert main([*args, "--truth-out", str(take)]) == 2
    one_line(capsys, "a file this command reads")
    assert (
        main(
            [*args[:3], str(tmp_path / "x.csv"), *args[4:], "--truth-out", str(tmp_path / "x.csv")]
        )
        == 2
    )
    one_line(capsys, "the same file")
    assert snapshot(tmp_path) == before


def test_clean_in_place_is_still_allowed(tmp_path, take):
    assert main(["clean", str(take), "-o", str(take), "--method", "ema", "--in-place"]) == 0
    assert io.load(take).n_frames == 120


def test_sigterm_during_clean_leaves_no_temporary_file(tmp_path):
    # today: SIGTERM left a .out.csv.XXXX.tmp of tens of MB behind (SIGINT cleaned up)
    big = tmp_path / "big.csv"
    t = np.arange(200_000) / 60.0
    io.save(Animation(t, np.full((len(t), 52), 0.5), ARKIT52, {"format": "csv"}), big)
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    cmd = [sys.executable, "-m", "faceclean", "clean", str(big), "-o", str(tmp_path / "out.csv")]
    proc = subprocess.Popen([*cmd, "--method", "ema"], env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not any(p.name.endswith(".tmp") for p in tmp_path.iterdir()):  # wait: it writes
        assert proc.poll() is None and time.monotonic() < deadline, "no temporary file seen"
        time.sleep(0.005)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143 and err.strip().splitlines()[-1] == "faceclean: terminated"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.csv"]


# -- class 4: data erased with exit 0 -------------------------------------------------------


@pytest.mark.parametrize("setting", ["r=1e300", "q=1e300", "r=1e-300"])
def test_a_cleaner_whose_output_is_not_finite_writes_nothing(tmp_path, take, setting, capsys):
    # today: --method kalman --set r=1e300 wrote a file where 99.9 % of the cells were empty
    out = tmp_path / "out.csv"
    rc = main(["clean", str(take), "-o", str(out), "--method", "kalman", "--set", setting])
    if rc == 0:  # a setting that still works must give a finite file
        assert np.isfinite(io.load(out).values).all()
    else:
        assert rc == 2 and not out.exists()
        one_line(capsys, "not finite")


def test_model_with_nan_scales_is_refused(tmp_path, take, capsys):
    from faceclean.io.npz_safe import load_arrays
    from faceclean.settings import MODELS

    arrays = load_arrays(MODELS / "default.npz")
    for k, a in arrays.items():  # every weight array NaN (whatever the shipped model's kind)
        if a.dtype.kind == "f":
            arrays[k] = np.full_like(a, np.nan)
    bad = tmp_path / "nan.npz"
    np.savez(bad, **arrays)
    assert main(["clean", str(take), "-o", str(tmp_path / "o.csv"), "--model", str(bad)]) == 2
    one_line(capsys, "finite")
    assert not (tmp_path / "o.csv").exists()


def test_tune_against_all_tracking_loss_is_refused(tmp_path, take, capsys):
    # today: a preset claiming MSE 0.0
    anim = io.load(take)
    lost = tmp_path / "lost.csv"
    io.save(anim.with_values(np.full_like(anim.values, np.nan)), lost)
    out = tmp_path / "p.json"
    assert main(["tune", str(take), "--truth", str(lost), "--method", "ema", "-o", str(out)]) == 2
    one_line(capsys, "nothing to tune on")
    assert not out.exists()


def test_relay_with_an_erasing_cleaner_does_not_start(capsys):
    assert main(["relay", "--listen", "vmc://:0", "--send", "vmc://:9", "--method", "kalman",
                 "--set", "r=1e300"]) == 2  # fmt: skip
    one_line(capsys, "finite")


# -- class 5 and 6: memory in proportion, one answer from both readers ----------------------


def test_symlink_to_dev_zero_and_a_fifo_are_refused_at_once(tmp_path, capsys):
    z = tmp_path / "zero.csv"
    z.symlink_to("/dev/zero")
    assert main(["info", str(z)]) == 2
    one_line(capsys, "character device")
    f = tmp_path / "fifo.npz"
    os.mkfifo(f)
    assert main(["info", str(f)]) == 2  # would block forever in open()
    one_line(capsys, "a FIFO")


def livelink(tmp_path: Path, timecode: bytes = b"16:48:50:05.000", cell: bytes = b"0.5") -> Path:
    head = b"Timecode,BlendshapeCount,JawOpen,EyeBlinkLeft\n"
    rows = [b"16:48:50:%02d.000,2,0.1,0.2\n" % i for i in range(4)]
    rows[2] = timecode + b",2," + cell + b",0.2\n"
    p = tmp_path / "ll.csv"
    p.write_bytes(head + b"".join(rows))
    return p


@pytest.mark.parametrize(
    "timecode",
    [b"99:99:99:99.999", b"16:60:50:05.000", b"16:48:50:75.000", b"9" * 400 + b":00:00:00.000",
     b"16:48:50:" + b"9" * 400],
)  # fmt: skip
def test_absurd_timecodes_are_refused_by_both_readers(tmp_path, timecode, capsys):
    # today: 99:99:99:99.999 was a midnight wrap (+24 h on every later frame); 400 digits
    # were refused by one reader and an internal error (or a time of inf) in the other
    src = livelink(tmp_path, timecode)
    assert main(["info", str(src)]) == 2
    a = one_line(capsys, "ll.csv line 4: ")  # a bad timecode, or a cell over 64 bytes
    assert main(["clean", str(src), "-o", str(tmp_path / "o.csv"), "--method", "ema"]) == 2
    assert one_line(capsys) == a  # the streaming reader says the same


def test_a_huge_cell_is_read_by_both_readers_at_its_number(tmp_path, capsys):
    # today: one 10 KB cell took 2.2 GB (info) and 3.9 GB (clean, the streaming path)
    from faceclean.io import livelink_csv

    src = livelink(tmp_path, cell=b"0." + b"0" * 10_000 + b"5")
    table = livelink_csv.parse_rows(src.read_bytes().splitlines(True)[1:], 1, 4, "x")[3]
    assert table.dtype.itemsize <= 64  # the cell table stays narrow
    anim = io.load(src)
    assert anim.values[2, 0] == float(b"0." + b"0" * 10_000 + b"5")
    out, mem = tmp_path / "o.csv", tmp_path / "m.csv"
    assert main(["clean", str(src), "-o", str(out), "--method", "ema"]) == 0  # streams
    io.save(filters.make("ema", {}, names=anim.names).clean(anim), mem)  # in memory
    assert out.read_bytes() == mem.read_bytes()
    word = livelink(tmp_path, cell=b"x" * 10_000)
    assert main(["info", str(word)]) == 2
    a = one_line(capsys, "not a number")
    assert main(["clean", str(word), "-o", str(out), "--method", "ema"]) == 2
    assert one_line(capsys) == a


def test_npz_that_unpacks_past_the_bound_is_refused(tmp_path, capsys):
    from faceclean.io import source

    p = tmp_path / "bomb.npz"
    n = source.MAX_UNPACKED // (8 * 52) + 1
    with open(p, "wb") as f:  # zeros compress ~1000:1
        np.savez_compressed(f, times=np.arange(n, dtype=float), values=np.zeros((n, 52)),
                            names=np.array(ARKIT52))  # fmt: skip
    assert p.stat().st_size < source.MAX_UNPACKED // 20
    assert main(["info", str(p)]) == 2
    one_line(capsys, "unpacks to")


# -- class 7: internal errors where a one-line reason belongs -------------------------------


@pytest.mark.parametrize(
    "value", ["1" + "0" * 400, "[" * 100_000 + "]" * 100_000, "1e400", "NaN", "[[1]]", "-Infinity"]
)
def test_absurd_set_values_are_one_line(tmp_path, take, value, capsys):
    out = tmp_path / "o.csv"
    assert (
        main(["clean", str(take), "-o", str(out), "--method", "ema", "--set", f"tau={value}"]) == 2
    )
    one_line(capsys, "tau")
    assert not out.exists()


@pytest.mark.parametrize(
    "body",
    ['{"format": "faceclean-preset/1", "method": "ema", "params": {"tau": 1' + "0" * 400 + "}}",
     '{"format": "faceclean-preset/1", "method": ["ema"], "params": {}}',
     '{"format": "faceclean-preset/1", "method": {"a": 1}, "params": {}}',
     '{"format": "faceclean-preset/1", "method": "ema", "params": {"tau": '
     + "[" * 50_000 + "]" * 50_000 + "}}",
     '{"format": "faceclean-preset/1", "method": "ema", "params": {"tau": Infinity}}'],
)  # fmt: skip
def test_absurd_presets_are_one_line(tmp_path, take, body, capsys):
    preset = tmp_path / "p.json"
    preset.write_text(body)
    assert main(["clean", str(take), "-o", str(tmp_path / "o.csv"), "--preset", str(preset)]) == 2
    one_line(capsys)


def model_with_config(tmp_path: Path, shipped: str = "lstm.npz", **change) -> Path:
    """A copy of a shipped model (the paper's LSTM, or the adaptive default) with config
    keys changed."""
    from faceclean.io.npz_safe import load_arrays
    from faceclean.settings import MODELS

    arrays = load_arrays(MODELS / shipped)
    config = json.loads(str(arrays["config"][()]))
    config.update(change)
    arrays["config"] = np.array(json.dumps(config))
    p = tmp_path / "model.npz"
    np.savez(p, **arrays)
    return p


@pytest.mark.parametrize(
    "change",
    [{"channels": [1, 2, 3]}, {"channels": "jawOpen"}, {"K": "one"}, {"K": 10**30},
     {"hidden": -1}, {"layers": 1e9}, {"value_range": "abc"}, {"value_range": [1, 0]},
     {"output": ["gated"]}],
)  # fmt: skip
def test_malformed_model_configs_are_one_line(tmp_path, take, change, capsys):
    model = model_with_config(tmp_path, **change)
    assert main(["clean", str(take), "-o", str(tmp_path / "o.csv"), "--model", str(model)]) == 2
    one_line(capsys, "model.npz")


@pytest.mark.parametrize(
    "change",
    [{"channels": [1, 2, 3]}, {"channels": "jawOpen"}, {"channels": ["jawOpen"] * 52},
     {"channels": []}, {"channels": None}, {"hidden": -1}, {"hidden": "32"},
     {"hidden": 32.0}, {"hidden": True}, {"hidden": 10**12}, {"embed": 0}, {"embed": None},
     {"hidden": 31}, {"format": "faceclean-adaptive/9"}],
)  # fmt: skip
def test_malformed_adaptive_configs_are_one_line(tmp_path, take, change, capsys):
    model = model_with_config(tmp_path, "default.npz", **change)
    assert main(["clean", str(take), "-o", str(tmp_path / "o.csv"), "--model", str(model)]) == 2
    one_line(capsys, "model.npz")
    assert not (tmp_path / "o.csv").exists()


def test_nonfinite_config_json_is_refused(tmp_path, take, capsys):
    from faceclean.io.npz_safe import load_arrays
    from faceclean.settings import MODELS

    arrays = load_arrays(MODELS / "lstm.npz")
    assert '"K": 1' in str(arrays["config"][()])
    arrays["config"] = np.array(str(arrays["config"][()]).replace('"K": 1', '"K": NaN'))
    p = tmp_path / "model.npz"
    np.savez(p, **arrays)
    assert main(["clean", str(take), "-o", str(tmp_path / "o.csv"), "--model", str(p)]) == 2
    one_line(capsys, "not valid JSON")


def test_truncated_mesh_is_one_line(tmp_path, take, capsys):
    from faceclean.face import mesh as facemesh
    from faceclean.io import gltf_take

    good = tmp_path / "face.glb"
    gltf_take.save_mesh(facemesh.stylised(), good)
    for cut in (0.5, 0.9):
        bad = tmp_path / "cut.glb"
        data = good.read_bytes()
        bad.write_bytes(data[: int(len(data) * cut)])
        assert main(["convert", str(take), "-o", str(tmp_path / "o.glb"), "--mesh", str(bad)]) == 2
        one_line(capsys)
    npz = tmp_path / "cut.npz"
    np.savez(tmp_path / "m.npz", neutral_vertices=np.zeros((3, 3)), faces=np.zeros((1, 3), int))
    npz.write_bytes((tmp_path / "m.npz").read_bytes()[:100])
    assert main(["convert", str(take), "-o", str(tmp_path / "o.glb"), "--mesh", str(npz)]) == 2
    one_line(capsys)


@pytest.mark.parametrize(
    "args, want",
    [(["synth", "-o", "{t}/s.csv", "--seed", "-1"], "seed"),
     (["synth", "-o", "{t}/s.csv", "--seed", str(2**64)], "seed"),
     (["corrupt", "{take}", "-o", "{t}/n.csv", "--seed", "1", "--strength", "1e308"], "strength"),
     (["corrupt", "{take}", "-o", "{t}/n.csv", "--seed", "-5"], "seed"),
     (["replay", "{take}", "--send", "vmc://127.0.0.1:9", "--speed", "1e-300"], "--speed"),
     (["replay", "{take}", "--send", "vmc://127.0.0.1:9", "--speed", "inf"], "--speed")],
)  # fmt: skip
def test_absurd_numeric_options_are_one_line(tmp_path, take, args, want, capsys):
    argv = [a.format(t=tmp_path, take=take) for a in args]
    assert main(argv) == 2
    one_line(capsys, want)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["take.csv"]


@pytest.mark.parametrize(
    "arrays",
    [{"pose": np.zeros(120), "pose_names": np.array(["HeadYaw"])},
     {"timecode_start": np.array(np.nan)}, {"timecode_start": np.array(np.inf)}],
    ids=["1d-pose", "nan-start", "inf-start"],
)  # fmt: skip
def test_npz_odd_passthrough_is_one_line_before_any_writer(tmp_path, take, arrays, capsys):
    anim = io.load(take)
    p = tmp_path / "a.npz"
    np.savez(p, times=anim.times, values=anim.values, names=np.array(anim.names), **arrays)
    assert main(["convert", str(p), "-o", str(tmp_path / "o.csv"), "--format", "livelink"]) == 2
    one_line(capsys)


def test_names_that_are_not_text_are_one_line(tmp_path, take, capsys):
    anim = io.load(take)
    for names in (np.arange(52), np.array(["\ud800"] + list(ARKIT52[1:]))):
        p = tmp_path / "a.npz"
        np.savez(p, times=anim.times, values=anim.values, names=names)
        assert main(["convert", str(p), "-o", str(tmp_path / "o.csv")]) == 2
        one_line(capsys)
    doc = {
        "format": "faceclean-animation/1",
        "channels": [1, 2],
        "times": [0.0],
        "values": [[0, 0]],
    }
    (tmp_path / "a.json").write_text(json.dumps(doc))
    assert main(["info", str(tmp_path / "a.json")]) == 2
    one_line(capsys)


def test_string_component_type_in_a_glb_is_one_line(tmp_path, take, capsys):
    src, data = gltf_with_uri(tmp_path, "buf.bin")
    (tmp_path / "buf.bin").write_bytes(data)
    doc = json.loads(src.read_text())
    doc["accessors"][1]["componentType"] = "5126"
    src.write_text(json.dumps(doc))
    assert main(["clean", str(src), "-o", str(tmp_path / "o.glb"), "--method", "ema"]) == 2
    one_line(capsys, "componentType")


# -- class 8: output that is not what it claims ---------------------------------------------


def test_info_json_is_strict_json_with_infinite_cells(tmp_path, take, capsys):
    anim = io.load(take)
    v = anim.values.copy()
    v[:, 0] = np.inf
    p = tmp_path / "inf.npz"
    io.save(anim.with_values(v), p)
    assert main(["info", str(p), "--json"]) == 0
    text = capsys.readouterr().out
    assert "Infinity" not in text and "NaN" not in text
    json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in info --json"))


@pytest.mark.parametrize("bad", [np.inf, -np.inf])
def test_info_says_the_range_of_the_finite_cells_and_counts_the_infinite(tmp_path, take, capsys,
                                                                         bad):  # fmt: skip
    anim = io.load(take)
    v = anim.values.copy()
    v[::2, :] = bad  # every channel has an infinite cell
    v[1, 0] = 1e308  # and one far past any weight
    p = tmp_path / "inf.npz"
    io.save(anim.with_values(v), p)
    assert main(["info", str(p)]) == 0
    shown = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("range"))
    low = float(v[1::2].min())  # the finite cells' least
    assert f"min {low:.4f}, max 1e+308" in shown and "infinite (read as missing)" in shown
    assert len(shown) < 400, shown  # no 309-digit numbers
    assert main(["info", str(p), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["infinite_cells"] == v[::2].size and facts["max"] == 1e308
    assert facts["min"] == low


def test_info_shows_a_name_s_escape_code_as_text_never_acts_on_it(tmp_path, capsys):
    from faceclean.animation import Animation

    p = tmp_path / "esc.csv"
    io.save(Animation(np.arange(5) / 30, np.zeros((5, 2)), ("jawOpen", "x\x1b[2Jy")), p,
            fmt="csv")  # fmt: skip
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "x\\x1b[2Jy" in out, out


def test_npz_bytes_names_are_names_and_complex_values_are_refused(tmp_path, take, capsys):
    anim = io.load(take)
    p = tmp_path / "b.npz"
    np.savez(
        p, times=anim.times, values=anim.values, names=np.array([n.encode() for n in anim.names])
    )
    assert io.load(p).names == anim.names  # today: "b'jawOpen'", never cleaned
    np.savez(p, times=anim.times, values=anim.values + 1j, names=np.array(anim.names))
    assert main(["info", str(p)]) == 2
    one_line(capsys, "complex")


def test_numpy_warnings_never_reach_stderr(tmp_path, capsys):
    p = tmp_path / "t.csv"
    t = np.array([-1e308, 1e308, 1.5e308, 1.7e308])
    io.save(Animation(t, np.full((4, 52), 0.5), ARKIT52, {"format": "csv"}), p)
    main(["clean", str(p), "-o", str(tmp_path / "o.csv"), "--method", "one-euro"])
    err = capsys.readouterr().err
    assert "Warning" not in err and "internal error" not in err


def test_library_never_imports_hypothesis():
    code = (
        "import sys, importlib, pkgutil, faceclean\n"
        "sys.modules['hypothesis'] = None\n"
        "for m in pkgutil.walk_packages(faceclean.__path__, 'faceclean.'):\n"
        "    if m.name not in ('faceclean.__main__', 'faceclean.evaluation.fuzz'):\n"
        "        importlib.import_module(m.name)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-500:]


def test_an_output_past_the_file_size_limit_is_one_line_and_leaves_nothing(tmp_path, take):
    # a real limit (ulimit -f, 8 blocks of 512 bytes: the cleaned take is larger)
    out = tmp_path / "o.csv"
    script = f"ulimit -f 8; exec {sys.executable} -m faceclean clean {take} -o {out}"
    r = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(lines) == 1, r.stderr
    assert "file size limit (ulimit -f)" in lines[0] and "Errno" not in lines[0]
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("suffix", [".csv", ".npz"])  # streamed block by block / in memory
def test_a_take_whose_times_restart_is_refused_not_held_still(tmp_path, capsys, suffix):
    # two recordings joined: every frame of the second is older than the first's last, and
    # a cleaner holds an old frame (repeats its last output): the face would freeze
    t = np.arange(240) / 60.0
    x = 0.5 + 0.4 * np.sin(2 * np.pi * t[:, None] + np.arange(52))
    joined = tmp_path / f"joined{suffix}"
    io.save(Animation(np.concatenate([t, t]), np.concatenate([x, x]), ARKIT52), joined)
    out = tmp_path / f"out{suffix}"
    assert main(["clean", str(joined), "-o", str(out)]) == 2
    one_line(capsys, "the times go back to 0.000 s after 3.983 s")
    assert not out.exists()
    far = np.concatenate([t[:10], [1e308], t[10:]])  # a time of 1e308: 300 digits were said
    io.save(Animation(far, np.concatenate([x[:11], x[10:]]), ARKIT52), joined)
    assert main(["clean", str(joined), "-o", str(out)]) == 2
    one_line(capsys, "the times go back to 0.167 s after 1e+308 s")
    io.save(Animation(np.zeros(240), x, ARKIT52), joined)  # times that never move: not "back"
    assert main(["clean", str(joined), "-o", str(out)]) == 2
    one_line(capsys, "the times stand still at 0.000 s (30 frames on)")
    late = np.concatenate([t[:100], t[80:85], t[100:]])  # five late frames: a tracker's jitter
    io.save(Animation(late, np.concatenate([x, x[:5]]), ARKIT52), joined)
    assert main(["clean", str(joined), "-o", str(out)]) == 0
