"""``faceclean info MODEL.npz`` describes a model file (it used to say the file lacked an
animation's arrays)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from faceclean.cli import main
from faceclean.settings import MODELS


def info(*args):
    return subprocess.run([sys.executable, "-m", "faceclean", "info", *map(str, args)],
                          capture_output=True, text=True)  # fmt: skip


@pytest.mark.parametrize(
    "model, method, channels",
    [("default.npz", "adaptive", 52), ("mediapipe.npz", "tracker-map", 51)],
)
def test_a_shipped_model_is_described(model, method, channels):
    r = info(MODELS / model)
    assert r.returncode == 0, r.stderr
    assert f"--method {method} --model FILE" in r.stdout
    assert f"channels    {channels}\n" in r.stdout and "parameters" in r.stdout
    facts = json.loads(info(MODELS / model, "--json").stdout)
    assert facts["config"]["format"].startswith("faceclean-")


def test_an_npz_that_is_neither_take_nor_model_is_still_one_line(tmp_path):
    import numpy as np

    p = tmp_path / "other.npz"
    np.savez(p, config=np.array('{"format": "someone-else/2"}'), w=np.zeros(3))
    r = info(p)
    assert r.returncode == 0 and "not a model faceclean runs" in r.stdout
    np.savez(p, junk=np.zeros(3))  # no config: read as a take, refused in one line
    r = info(p)
    assert r.returncode != 0 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    for fmt in ("[1]", '{"a": 1}'):  # a format that is no name: one line, never a TypeError
        np.savez(p, config=np.array(f'{{"format": {fmt}}}'), w=np.zeros(3))
        r = info(p)
        assert r.returncode == 2 and "format is not a name" in r.stderr, r.stderr
        assert r.stderr.count("\n") == 1 and "internal error" not in r.stderr


def test_steps_too_small_to_be_frames_give_no_rate(tmp_path, capsys):
    # third red team: a 5e-324 s step printed "rate inf Hz"; such steps are duplicates
    from faceclean.animation import Animation

    path = tmp_path / "t.csv"
    path.write_text("time,jawOpen\n0,0\n5e-324,0.1\n1e-323,0.2\n")
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "inf" not in out and "rate        0.000 Hz" in out
    assert Animation(np.array([0.0, 1e-300, 2e-300]), np.zeros((3, 1)), ["jawOpen"]).rate == 0.0
