"""Prompts a tracker cannot show (guided/reading.py) are placed by timing, not held against
the take (issue 35): a MediaPipe take of the script whose jawLeft/Right/Forward, cheekPuff,
mouthFrown and noseSneer stay at 0 is accepted; a still or random one is still refused;
ARKit input still needs every prompt.

The takes are synthesized as tests/test_guided.py's fast tests do: the script performed
late, slow and uneven, read with a face's own gain and noise, in MediaPipe's channels (its
scores of what it reads; 0 plus noise on what it does not), then cleaned by the shipped map
as ``calibrate --guided --tracker mediapipe`` does.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.cli import main
from faceclean.guided import reading
from faceclean.guided.fit import guided
from faceclean.guided.script import TAIL, load
from faceclean.trackers.mediapipe import NAMES

SCRIPT = load()
RATE = 24.0
PLACED = {"jaw_left", "jaw_right", "jaw_forward", "frown", "cheek_puff", "sneer"}


def performed(late: float = 1.2, speed: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """(take times, script times): late by ``late`` s, then at ``speed`` of the script's
    pace, uneven (+-0.15 over 7 s)."""
    tau = np.arange(int((late + SCRIPT.seconds / (speed - 0.15) + 1.0) * RATE)) / RATE
    s = np.cumsum(speed + 0.15 * np.sin(2 * np.pi * tau / 7.0)) / RATE
    return tau, np.where(tau < late, 0.0, s - np.interp(late, tau, s))


def mediapipe_take(w: np.ndarray, seed: int = 0) -> np.ndarray:
    """(N, 51) MediaPipe scores of weights ``w`` (N, 52): 0.9x with noise where it reads,
    about 0 where it does not."""
    rng = np.random.default_rng(seed)
    x = 0.9 * w[:, [ARKIT52.index(n) for n in NAMES]] + rng.normal(0, 0.01, (len(w), len(NAMES)))
    for j, name in enumerate(NAMES):
        if name in reading.unread("mediapipe"):
            x[:, j] = np.abs(rng.normal(0, 0.002, len(w)))
    return np.clip(x, 0, 1)


def test_a_script_take_mediapipe_reads_is_accepted_with_unread_prompts_placed(tmp_path, capsys):
    tau, s = performed()
    take, out = tmp_path / "take.csv", tmp_path / "calib.json"
    io.save(Animation(tau, mediapipe_take(SCRIPT.weights(s)), NAMES), take, fmt="csv")
    assert main(["calibrate", "--guided", str(take), "-o", str(out), "--tracker", "mediapipe"]) == 0
    lines = capsys.readouterr().out.splitlines()
    jaw = next(line for line in lines if line.startswith("jaw_left "))
    assert "placed by timing (MediaPipe does not read jawLeft)" in jaw
    assert not any("not performed" in line for line in lines)
    facts = json.loads(out.read_text())["calibration"]["guided"]
    assert set(facts["placed"]) == PLACED and facts["follows"]

    a = guided(io.load(take), "mediapipe").alignment
    assert a.follows and a.shortfall() is None and a.placed == len(PLACED)
    for g in a.segments:  # placed where the person really did it, within 0.5 s
        assert g.seen or (g.placed and g.prompt.id in PLACED), g.prompt.id
        true0, true1 = tau[np.searchsorted(s, [g.prompt.start, g.prompt.end])]
        if g.placed:
            assert abs(g.t0 - true0) < 0.5 and abs(g.t1 - true1) < 0.5, g.prompt.id


def test_an_unread_prompt_with_its_face_lost_is_still_held_against_the_take(tmp_path):
    tau, s = performed()
    x = mediapipe_take(SCRIPT.weights(s))
    puff = next(p for p in SCRIPT.prompts if p.id == "cheek_puff")
    x[(s > puff.start - 0.5) & (s < puff.end + 0.5)] = np.nan  # no face there
    a = guided(Animation(tau, x, NAMES), "mediapipe").alignment
    assert a.follows and "cheek_puff (face lost)" in str(a.shortfall())


@pytest.mark.parametrize("kind", ["still", "random"])
def test_still_and_random_mediapipe_takes_are_still_refused(tmp_path, capsys, kind):
    from faceclean.datasets.performer import perform

    n = int((SCRIPT.seconds + TAIL) * RATE)  # the live recording's length
    t = np.arange(n) / RATE
    if kind == "still":
        w = np.zeros((n, len(ARKIT52)))
    else:
        w, _ = perform(n / RATE, seed=3, fps=RATE).arkit()
        w = w[:n]
    take, out = tmp_path / "take.csv", tmp_path / "calib.json"
    io.save(Animation(t, mediapipe_take(w), NAMES), take, fmt="csv")
    assert main(["calibrate", "--guided", str(take), "-o", str(out), "--tracker", "mediapipe"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and not out.exists()
    assert "did not follow the script" in err and "6 more that MediaPipe does not read" in err


def test_arkit_input_still_needs_every_prompt(tmp_path, capsys):
    tau, s = performed()
    w = SCRIPT.weights(s)
    w[:, [ARKIT52.index(n) for n in reading.unread("mediapipe")]] = 0.0  # ARKit reads them
    take, out = tmp_path / "take.csv", tmp_path / "calib.json"
    io.save(Animation(tau, 0.9 * w, ARKIT52), take, fmt="csv")
    assert main(["calibrate", "--guided", str(take), "-o", str(out), "--tracker", "arkit"]) == 2
    err = capsys.readouterr().err
    assert "6 prompts not seen" in err and "jaw_left (not performed)" in err
    assert "placed" not in err and not out.exists()


def test_the_unread_list_is_what_survey_measures():
    from faceclean.trackers.signature import SILENT

    rng = np.random.default_rng(1)
    t = np.arange(400) / 30
    truth = np.clip(rng.uniform(-0.5, 1.0, (len(t), 52)), 0, 1)
    raw = truth.copy()
    raw[:, ARKIT52.index("jawLeft")] *= 0.04  # moved, barely read
    raw[:, ARKIT52.index("eyeWideLeft")] *= 0.2  # under-read, but read
    found = reading.survey([(Animation(t, raw, ARKIT52), Animation(t, truth, ARKIT52))])
    assert reading.not_read(found) == ("jawLeft",)
    assert found["eyeWideLeft"][1] >= reading.READ_MIN
    # the signature of raw MediaPipe (channels it keeps near 0) is among those it does not read
    assert set(SILENT) <= reading.unread("mediapipe") and not reading.unread("arkit")
