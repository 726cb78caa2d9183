"""A studio's own guided script (``--script FILE``): printed as the file it reads, performed,
fitted, and refused in one line when it is not a script or not where a script goes."""

from __future__ import annotations

import copy
import json
import os

import numpy as np
import pytest
from test_guided import SHORT, arkit_face, performed

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.cli import main
from faceclean.guided.script import MAX_PROMPTS, from_dict, load


def test_the_shipped_script_prints_as_the_file_script_reads(tmp_path, capsys):
    assert main(["calibrate", "--print-script", "json"]) == 0
    path = tmp_path / "mine.json"
    path.write_text(capsys.readouterr().out)
    assert load(path) == load()  # every prompt, time, aim, ramp and weight
    assert main(["calibrate", "--print-script", "--script", str(short_file(tmp_path))]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "a short one (6.6 s, 5 prompts)" and "Frown" in out[4]


def short_file(tmp_path, doc=SHORT):
    path = tmp_path / "short.json"
    path.write_text(json.dumps(doc))
    return path


def test_a_take_of_ones_own_script_calibrates_with_it(tmp_path, capsys):
    script = from_dict(SHORT)
    tau, s = performed(late=0.6, speed=0.9, rate=60.0, script=script)
    take = tmp_path / "take.csv"
    io.save(Animation(tau, arkit_face(script.weights(s)), ARKIT52), take)
    out = tmp_path / "calib.json"
    argv = ["calibrate", "--guided", str(take), "-o", str(out), "--tracker", "arkit"]
    assert main([*argv, "--script", str(short_file(tmp_path))]) == 0
    printed = capsys.readouterr().out
    rows = [line.split() for line in printed.splitlines()[1:6]]
    assert [r[0] for r in rows] == [p["id"] for p in SHORT["prompts"]]
    assert all("seen" in r for r in rows), printed
    facts = json.loads(out.read_text())["calibration"]
    assert facts["guided"]["script"] == "a short one" and not facts["guided"]["not_seen"]
    gain = facts["channels"]["mouthSmileLeft"]["gain"]
    assert gain == pytest.approx(1 / 0.5, rel=0.1)  # this face's small smile reaches the aim
    # without --script the take is held against the shipped one (33.9 s): refused
    out.unlink()
    assert main(argv) == 2
    assert "shorter than the script (33.9 s)" in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize("case", ["not json", "no neutral first", "overlap", "too many",
                                  "too long", "a folder", "a fifo", "keys of one",
                                  "keys of three", "keys a number", "keys text",
                                  "nothing aimed at", "a weight of 1e300",
                                  "an escape code", "a prompt of 0 s", "an id twice",
                                  "a title not text", "every target 0", "a text not text",
                                  "a key after its prompt"])  # fmt: skip
def test_a_bad_script_is_one_line_and_nothing_is_written(tmp_path, capsys, case):
    doc = copy.deepcopy(SHORT)
    path = tmp_path / "bad.json"
    if case == "not json":
        path.write_text("{prompts: [")
    elif case == "no neutral first":
        doc["prompts"] = doc["prompts"][1:]
    elif case == "overlap":
        doc["prompts"][2]["start"] = 2.5
    elif case == "too many":
        doc["prompts"] = [{"id": f"p{k}", "start": 2.0 * k, "duration": 1.0}
                          for k in range(MAX_PROMPTS + 1)]  # fmt: skip
    elif case == "too long":
        doc["prompts"][-1]["duration"] = 900.0
    elif case.startswith("keys"):  # the shape of keys: [[seconds, {weights}], ...]
        doc["prompts"][1]["keys"] = {"keys of one": [[0.0]], "keys of three": [[0.0, {}, 5]],
                                     "keys a number": [5], "keys text": "abc"}[case]  # fmt: skip
    elif case == "nothing aimed at":  # a neutral hold alone: nothing to fit
        doc["prompts"] = doc["prompts"][:1]
    elif case == "an escape code":  # a terminal acts on it where the prompt is shown
        doc["prompts"][1]["text"] = "Smile\x1b[2J"
    elif case == "a weight of 1e300":
        doc["prompts"][1]["targets"] = {"jawOpen": 1e300}
    elif case == "a prompt of 0 s":  # no frame of the alignment's grid: an internal error
        doc["prompts"][1]["duration"] = 0.0
    elif case == "an id twice":
        doc["prompts"][2]["id"] = doc["prompts"][1]["id"]
    elif case == "a title not text":
        doc["title"] = {"x": 1}
    elif case == "every target 0":  # aims at channels, at 0: nothing to align on
        for p in doc["prompts"][1:]:
            p["targets"] = {n: 0.0 for n in p.get("targets", {})}
    elif case == "a text not text":  # second red team: null was shown as the prompt "None"
        doc["prompts"][1]["text"] = None
    elif case == "a key after its prompt":  # ... and a key at 99 s of a 1.1 s prompt taken
        doc["prompts"][2]["keys"] = [[0.0, {"jawOpen": 0.2}], [99.0, {"jawOpen": 0.5}]]
    elif case == "a folder":
        path = tmp_path
    elif case == "a fifo":
        path = tmp_path / "fifo.json"
        os.mkfifo(path)
    if case not in ("not json", "a folder", "a fifo"):
        path.write_text(json.dumps(doc))
    take = tmp_path / "take.csv"
    io.save(Animation(np.arange(240) / 30, np.zeros((240, 52)), ARKIT52), take)  # 8 s
    out = tmp_path / "calib.json"
    guided = ["calibrate", "--guided", str(take), "-o", str(out)]
    said = {
        "a prompt of 0 s": "at least 0.3 s",
        "an id twice": "given twice",
        "a title not text": "title is a string",
        "every target 0": "aims at a channel above 0",
        "a text not text": "its text is a string",
        "a key after its prompt": "has a key after its 1.1 s",
    }
    for argv in (["calibrate", "--print-script"], guided):
        assert main([*argv, "--script", str(path)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err, err
        assert "internal error" not in err and not out.exists()
        if case == "a weight of 1e300":  # the limit said is the one broken
            assert "a weight from 0 to 1" in err, err
        assert said.get(case, "") in err, err


def test_script_goes_only_where_a_guided_script_is_used(tmp_path, capsys):
    path = short_file(tmp_path)
    take = tmp_path / "take.csv"
    io.save(Animation(np.arange(60) / 30, np.zeros((60, 52)), ARKIT52), take)
    for argv, words in (
        (["calibrate", str(take), "-o", str(tmp_path / "c.json")], "give it with --guided"),
        (["relay", "--listen", "vmc://127.0.0.1:0", "--send", "vmc://127.0.0.1:9"],
         "give it with --ui"),
        (["track", "in.mp4", "-o", str(tmp_path / "o.csv")], "go with --camera"),
    ):  # fmt: skip
        assert main([*argv, "--script", str(path)]) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "c.json").exists() and not (tmp_path / "o.csv").exists()


def test_a_script_in_the_performers_language_prints_where_the_terminal_cannot_show_it(tmp_path):
    import subprocess
    import sys

    doc = copy.deepcopy(SHORT)
    doc["prompts"][1]["text"] = "Souriez \u2014 grand sourire, \u00e7a y est"
    path = tmp_path / "fr.json"
    path.write_text(json.dumps(doc, ensure_ascii=False), encoding="utf-8")
    env = {**os.environ, "PYTHONIOENCODING": "ascii"}  # a terminal of ASCII alone
    argv = [sys.executable, "-m", "faceclean", "calibrate", "--print-script", "--script", path]
    r = subprocess.run(argv, capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    assert "Souriez \\u2014 grand sourire, \\xe7a y est" in r.stdout
