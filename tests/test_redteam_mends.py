"""Red team, fourth round: what ``convert``, ``corrupt``, ``tune`` and ``clean --model``
let through, mended.

- the Live Link writer: a NaN cell is written empty (read back as missing), an infinite
  one refused in one line, as the JSON writer refuses it;
- times that go back or stand still: refused by ``convert``, ``corrupt`` and ``tune`` with
  ``clean``'s own check (timing.Restarts); times float64 cannot step at a frame's length
  refused by the simulator;
- two outputs of one command (``corrupt --truth-out``): both written, then both renamed
  (io.atomic.together), so a full disk at the second replaces neither;
- an ONNX model's external data: refused, never read from the current folder.

Black box where a command is the surface: ``faceclean`` in a subprocess with a timeout.
"""

from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import not_installed
from test_redteam import _env, fc, no_temp_files, ok, plain_text, refused

from faceclean import io

TIMEOUT = 60.0  # s: each command here takes a second or two


def _take(path: Path, n: int = 120, times=None, values=None) -> Path:
    path.write_bytes(plain_text(n, times=times, values=values))
    return path


# --------------------------------------------------------------------------------------
# 1. Live Link output: NaN kept as a gap, infinity refused


def test_livelink_output_refuses_infinite_cells(tmp_path):
    x = np.full((40, 52), 0.25)
    x[5, 3], x[6, 4], x[7, 5] = np.nan, np.inf, -np.inf
    src = _take(tmp_path / "naninf.csv", values=x)
    out = tmp_path / "nl.csv"
    r = fc("convert", src, "-o", out, "--format", "livelink", timeout=TIMEOUT)
    refused(r)
    assert "Live Link CSV cannot hold infinite values" in r.stderr, r.stderr
    assert not out.exists()
    no_temp_files(tmp_path)


def test_livelink_output_keeps_a_missing_cell_missing(tmp_path):
    x = np.full((40, 52), 0.25)
    x[5, 3] = np.nan  # one cell the tracker did not give
    src = _take(tmp_path / "nan.csv", values=x)
    out = tmp_path / "nl.csv"
    ok(fc("convert", src, "-o", out, "--format", "livelink", timeout=TIMEOUT))
    got, present = io.load(out).arkit(io.load(src).names)  # (40, 52) in the source's order
    assert present.all()
    assert np.isnan(got[5, 3]), "the gap was written as a number"
    assert np.isnan(got).sum() == 1
    np.testing.assert_allclose(np.nan_to_num(got, nan=0.25), 0.25)


# --------------------------------------------------------------------------------------
# 2. Times that do not increase: refused as clean refuses them


def _reversed(tmp_path: Path) -> Path:
    return _take(tmp_path / "reversed.csv", times=(np.arange(120) / 60.0)[::-1])


def _same(tmp_path: Path) -> Path:
    return _take(tmp_path / "sametime.csv", times=np.zeros(120))


@pytest.mark.parametrize("make", [_reversed, _same], ids=["reversed", "same-time"])
@pytest.mark.parametrize(
    "command",
    [
        ["convert", "{IN}", "-o", "{DIR}/x.json"],
        ["convert", "{IN}", "-o", "{DIR}/x.glb"],
        ["corrupt", "{IN}", "-o", "{DIR}/x.csv", "--seed", "1", "--preset", "mixed"],
        ["tune", "{IN}", "--truth", "{IN}", "--method", "ema", "-o", "{DIR}/q.json"],
        ["replay", "{IN}", "--send", "livelink://127.0.0.1:9"],  # would go unpaced
    ],
    ids=["convert-json", "convert-glb", "corrupt", "tune", "replay"],
)
def test_times_that_do_not_increase_are_refused(tmp_path, make, command):
    src = make(tmp_path)
    argv = [a.replace("{IN}", str(src)).replace("{DIR}", str(tmp_path)) for a in command]
    r = fc(*argv, timeout=TIMEOUT)
    refused(r)
    assert "give it increasing times" in r.stderr, r.stderr  # clean's own message
    assert sorted(p.name for p in tmp_path.iterdir()) == [src.name]


def test_corrupt_refuses_times_float64_cannot_step(tmp_path):
    src = _take(tmp_path / "bigtime.csv", times=1e15 + np.arange(120) / 60.0)
    out = tmp_path / "x.csv"
    r = fc("corrupt", src, "-o", out, "--seed", "1", "--preset", "mixed", timeout=TIMEOUT)
    refused(r)
    assert "too large" in r.stderr, r.stderr
    assert not out.exists()


def test_corrupt_refuses_a_short_take_at_one_time(tmp_path):
    src = _take(tmp_path / "sametime.csv", n=10, times=np.zeros(10))  # < Restarts' run
    out = tmp_path / "x.csv"
    refused(fc("corrupt", src, "-o", out, "--seed", "1", timeout=TIMEOUT))
    assert not out.exists()


# --------------------------------------------------------------------------------------
# 3. Two outputs: both or neither


def test_corrupt_full_disk_at_the_second_output_replaces_neither(tmp_path):
    """RLIMIT_FSIZE stands in for a full disk: the noisy NPZ (~80 KB) fits, the truth CSV
    (~190 KB) does not; before, the noisy file was replaced and the truth kept its old
    content."""
    src = _take(tmp_path / "take.csv", n=180)
    noisy, truth = tmp_path / "n.npz", tmp_path / "tr.csv"
    noisy.write_bytes(b"old noisy")
    truth.write_bytes(b"old truth")
    cmd = [sys.executable, "-m", "faceclean", "corrupt", str(src), "-o", str(noisy)]
    cmd += ["--truth-out", str(truth), "--seed", "1"]
    size = 128 << 10

    def small_files():
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))

    r = subprocess.run(cmd, env=_env(), capture_output=True, text=True, preexec_fn=small_files,
                       timeout=TIMEOUT)  # fmt: skip
    assert r.returncode == 1, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and r.stderr.startswith("faceclean: ")
    assert noisy.read_bytes() == b"old noisy"
    assert truth.read_bytes() == b"old truth"
    no_temp_files(tmp_path)
    ok(fc(*cmd[3:], timeout=TIMEOUT))  # without the limit: both written
    assert io.load(noisy).n_frames == io.load(truth).n_frames


def test_together_renames_nothing_when_the_block_fails(tmp_path):
    from faceclean.io.atomic import atomic_write, together

    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    with pytest.raises(RuntimeError), together():
        atomic_write(a, "new a")
        atomic_write(b, "new b")
        assert a.read_text() == "old a"  # written, not yet renamed
        raise RuntimeError("the second output failed")
    assert a.read_text() == "old a" and not b.exists()
    no_temp_files(tmp_path)
    with together():
        atomic_write(a, "new a")
        atomic_write(b, "new b")
    assert (a.read_text(), b.read_text()) == ("new a", "new b")
    no_temp_files(tmp_path)


# --------------------------------------------------------------------------------------
# 4. ONNX external data: never read from the current folder (nor beside the model)


def _external_model(folder: Path, data_name: str) -> Path:
    """The shipped LSTM as a step graph with its weights in ``folder / data_name``."""
    onnx = pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    from onnx import external_data_helper

    from faceclean.learned.checkpoint import LSTMWeights
    from faceclean.learned.export import build
    from faceclean.settings import MODELS

    model = build(LSTMWeights.load(MODELS / "lstm.npz"))
    external_data_helper.convert_model_to_external_data(
        model, all_tensors_to_one_file=True, location=data_name, size_threshold=1024
    )
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "ext.onnx"
    onnx.save_model(model, path)
    assert (folder / data_name).is_file()
    return path


def test_onnx_external_data_in_the_current_folder_is_not_read(tmp_path):
    _external_model(tmp_path / "ox", "w0.bin")
    (tmp_path / "ox" / "w0.bin").rename(tmp_path / "w0.bin")  # only in the current folder
    src = _take(tmp_path / "s.csv")
    r = fc("clean", src.name, "--model", "ox/ext.onnx", "-o", "o.csv", cwd=tmp_path,
           timeout=TIMEOUT)  # fmt: skip
    refused(r)
    assert "external data" in r.stderr, r.stderr
    assert not (tmp_path / "o.csv").exists()


def test_onnx_external_data_beside_the_model_is_refused_in_one_line(tmp_path):
    model = _external_model(tmp_path / "ox", "w0.bin")
    src = _take(tmp_path / "s.csv")
    r = fc("clean", src, "--model", model, "-o", tmp_path / "o.csv", timeout=TIMEOUT)
    refused(r)
    assert "external data" in r.stderr, r.stderr


NO_ONNX = (
    not_installed("onnx")
    + """
from faceclean.errors import FacecleanError
from faceclean.learned.onnx import OnnxLearned
try:
    OnnxLearned(sys.argv[1])
except FacecleanError as e:
    print(e)
else:
    print("loaded")
"""
)


def test_onnx_external_data_refused_by_onnxruntime_alone(tmp_path):
    """Without the onnx package (onnxruntime only), the session's empty data folder still
    keeps the current folder's file unread."""
    _external_model(tmp_path / "ox", "w0.bin")
    (tmp_path / "ox" / "w0.bin").rename(tmp_path / "w0.bin")
    r = subprocess.run([sys.executable, "-c", NO_ONNX, "ox/ext.onnx"], cwd=tmp_path,
                       env=_env(), capture_output=True, text=True, timeout=TIMEOUT)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "external data" in r.stdout, r.stdout


@pytest.mark.parametrize("names", [[f"c{j}" for j in range(5000)], ["x" * 300, "jawOpen"]],
                         ids=["5000-channels", "a-300-byte-name"])  # fmt: skip
def test_a_csv_its_own_reader_would_refuse_is_not_written(tmp_path, names):
    from faceclean.animation import Animation

    src, out = tmp_path / "wide.npz", tmp_path / "wide.csv"
    io.save(Animation(np.arange(5) / 30.0, np.full((5, len(names)), 0.5), tuple(names)), src)
    r = fc("convert", src, "-o", out, timeout=TIMEOUT)
    refused(r)
    assert "write .npz or .json" in r.stderr and not out.exists(), r.stderr


@pytest.mark.parametrize("out", [".", "/dev/null"])
def test_an_output_with_no_extension_says_which_it_is_and_what_to_name(tmp_path, out):
    r = fc("synth", "-o", out, "--seconds", "1", timeout=TIMEOUT, cwd=tmp_path)
    refused(r)
    assert f"{out}: unknown output type '(no extension)': name a file ending .csv" in r.stderr
