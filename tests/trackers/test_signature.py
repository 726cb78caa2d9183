"""trackers/signature.py: raw MediaPipe passes; remapped, quantised or rescaled input is
said once, by ``clean --tracker mediapipe`` and by the relay's stream wrapper."""

from __future__ import annotations

import glob
import os

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.cli import main
from faceclean.trackers.signature import MIN_FRAMES, Watch, judge

NAMES = tuple(n for n in ARKIT52 if n != "tongueOut")  # what MediaPipe gives
SILENT = ("cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight",
          "cheekPuff", "jawForward")  # fmt: skip


def mediapipe_like(n: int = 300, seed: int = 0) -> np.ndarray:
    """(n, 51) float32-precision scores as MediaPipe gives them: moving channels in parts
    of [0, 1], the channels it keeps near 0 under 0.01."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 30.0
    x = 0.05 + 0.3 * np.abs(np.sin(t[:, None] * rng.uniform(0.5, 3, len(NAMES))))
    x += rng.normal(0, 0.01, x.shape)
    for name in SILENT:
        x[:, NAMES.index(name)] = rng.uniform(0, 0.006, n)
    return np.clip(x, 0, 1).astype(np.float32).astype(np.float64)


def test_mediapipe_like_scores_pass_and_each_sign_is_found():
    x = mediapipe_like()
    assert judge(x, NAMES) is None
    moved = x.copy()
    moved[100:120, NAMES.index("noseSneerLeft")] = 0.4
    assert "noseSneerLeft reaches 0.40" in judge(moved, NAMES)
    with_tongue = np.hstack([x, np.zeros((len(x), 1))])
    with_tongue[50, -1] = 0.3
    assert "tongueOut" in judge(with_tongue, (*NAMES, "tongueOut"))
    assert "quantised" in judge(np.round(x, 2), NAMES)
    lo, hi = x.min(0), x.max(0)
    rescaled = (x - lo) / np.where(hi - lo > 0.05, hi - lo, 1.0)
    assert "whole 0-1 range" in judge(rescaled, NAMES)
    assert judge(np.round(x, 2)[: MIN_FRAMES - 1], NAMES) is None  # too little to tell
    assert judge(np.full((10, len(NAMES)), np.nan), NAMES) is None  # no face at all


def test_a_long_take_is_judged_on_rows_spread_over_it_and_an_infinite_reading_is_no_level():
    """Past SAMPLE rows sign 2 reads levels on rows spread over the take (an hour's sort
    cost 0.3 s); a channel that moves only late in the take is read there too."""
    from faceclean.trackers.signature import SAMPLE

    x = mediapipe_like(3 * SAMPLE + 7, seed=3)
    assert judge(x, NAMES) is None
    assert "quantised" in judge(np.round(x, 2), NAMES)
    late = np.round(x, 2)
    late[: 2 * SAMPLE] = late[0]  # still for two thirds, then moving in steps of 0.01
    assert "quantised" in judge(late, NAMES)
    x[5, 3], x[9, NAMES.index("jawForward")] = np.inf, -np.inf  # not levels, not frames lost
    assert judge(x, NAMES) is None
    x[10:20] = np.nan
    x[11, 0] = 0.2  # a row with one value is a face frame
    q = np.round(x, 2)
    assert judge(q[: MIN_FRAMES + 8], NAMES) is None  # 59 frames with a face: too few
    assert "quantised" in judge(q[: MIN_FRAMES + 9], NAMES)  # 60, row 11 among them


def test_real_mediapipe_takes_pass():
    """The rule's data: every finished (tracked, truth) pair in the families cache."""
    root = os.path.expanduser("~/.cache/faceclean/families")
    files = [f for f in sorted(glob.glob(f"{root}/*.tracked.csv"))
             if os.path.exists(f.replace(".tracked.csv", ".json"))]  # fmt: skip
    if len(files) < 5:
        pytest.skip("no tracked pairs in ~/.cache/faceclean/families")
    flagged = [f for f in files[:40] if judge(*_vn(io.load(f))) is not None]
    assert flagged == []
    rounded = [judge(np.round(v, 2), n) for v, n in map(_vn, map(io.load, files[:10]))]
    assert sum(r is not None for r in rounded) >= 9


def _vn(anim: Animation):
    return anim.values, anim.names


def _take(values: np.ndarray, names) -> Animation:
    t = np.arange(len(values)) / 30.0
    return Animation(t, values, tuple(names), {"format": "csv"})


def test_clean_tracker_mediapipe_warns_once_on_a_take_that_is_not_raw(tmp_path, capsys):
    raw, remapped = tmp_path / "raw.npz", tmp_path / "remapped.npz"
    x = mediapipe_like()
    io.save(_take(x, NAMES), raw)
    y = x.copy()
    y[:, NAMES.index("noseSneerLeft")] = 0.3 + 0.1 * np.sin(np.arange(len(x)) / 9.0)
    io.save(_take(y, NAMES), remapped)
    assert main(["clean", str(raw), "-o", str(tmp_path / "a.npz"), "--tracker", "mediapipe"]) == 0
    assert "warning" not in capsys.readouterr().err
    out = str(tmp_path / "b.npz")
    assert main(["clean", str(remapped), "-o", out, "--tracker", "mediapipe"]) == 0
    err = capsys.readouterr().err
    assert err.count("does not look like raw MediaPipe") == 1 and "noseSneerLeft" in err
    assert main(["clean", str(remapped), "-o", out, "--method", "one-euro"]) == 0
    assert "warning" not in capsys.readouterr().err  # only --tracker mediapipe asks


def test_a_streamed_clean_warns_too(tmp_path, capsys):
    src = tmp_path / "q.csv"
    io.save(_take(np.round(mediapipe_like(), 2), NAMES), src, fmt="livelink")
    out = str(tmp_path / "o.csv")
    assert main(["clean", str(src), "-o", out, "--tracker", "mediapipe"]) == 0
    err = capsys.readouterr().err
    assert err.count("does not look like raw") == 1 and "(quantised)" in err


class _Echo:
    """Gives each frame back; a missing value holds the last one (the time rules)."""

    name = "echo"

    def __init__(self) -> None:
        self.resets = 0
        self.last = np.zeros(len(ARKIT52))

    def reset(self) -> None:
        self.resets += 1
        self.last = np.zeros(len(ARKIT52))

    def step(self, frame, t):
        self.last = np.where(np.isnan(frame), self.last, frame)
        return self.last.copy()


def test_watch_warns_once_forgets_warm_up_and_steps_as_its_cleaner():
    from faceclean.relay.loop import warm_up

    said = []
    inner = _Echo()
    watch = Watch(inner, ARKIT52, said.append)
    warm_up(watch)  # random frames, tongueOut included: forgotten at the reset
    assert inner.resets == 1 and said == []
    x = np.hstack([mediapipe_like(200), np.full((200, 1), np.nan)])  # tongueOut absent
    for i, row in enumerate(x):
        np.testing.assert_array_equal(watch.step(row, i / 30.0)[:-1], row[:-1])
    assert said == []
    x[:, ARKIT52.index("tongueOut")] = 0.5
    for i, row in enumerate(np.vstack([x, x])):
        watch.step(row, 10 + i / 30.0)
    assert len(said) == 1 and "tongueOut" in said[0]
    assert watch.name == "echo"  # the inner cleaner's attributes show through


def test_watch_judges_a_block_as_it_judges_frames_and_cleans_as_its_cleaner():
    # a long file goes through ``steps`` a block at a time (issue 38): the watch must see
    # those frames too (once it did not, and a streamed clean of an hour said nothing)
    from faceclean.filters.one_euro import OneEuro

    x = np.round(mediapipe_like(400), 2)  # quantised: not raw MediaPipe
    t = np.arange(len(x)) / 30.0
    said, by_frame = [], []
    block = Watch(OneEuro(names=NAMES), NAMES, said.append)
    frames = Watch(OneEuro(names=NAMES), NAMES, by_frame.append)
    for w in (block, frames):
        w.reset()
    out = np.vstack([block.steps(t[:150], x[:150]), block.steps(t[150:], x[150:])])
    want = np.array([frames.step(row, ti) for row, ti in zip(x, t, strict=True)])
    assert said == by_frame and len(said) == 1 and "quantised" in said[0]
    np.testing.assert_array_equal(out, want)
    quiet = []
    raw = Watch(OneEuro(names=NAMES), NAMES, quiet.append)
    raw.reset()
    raw.steps(t, mediapipe_like(400))
    assert quiet == []


def test_relay_tracker_mediapipe_warns_once_on_a_stream_that_is_not_raw():
    """The relay process, a VMC stream whose tongueOut moves (MediaPipe has none)."""
    import select
    import subprocess
    import sys
    import time

    from helpers import REPO, interrupt, reaped
    from pythonosc.udp_client import UDPClient

    sys.path.insert(0, str(REPO / "tests" / "relay"))
    from test_relay_loopback import raw_receiver, vmc_bundle

    names = ["jawOpen", "eyeBlinkLeft", "tongueOut"]
    with raw_receiver() as rx:
        send = f"vmc://127.0.0.1:{rx.getsockname()[1]}"
        cmd = [sys.executable, "-m", "faceclean", "relay", "--listen", "vmc://127.0.0.1:0"]
        cmd += ["--send", send, "--tracker", "mediapipe"]
        pipe = subprocess.PIPE
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=pipe, stderr=pipe, text=True)
        with reaped(proc):
            ready, _, _ = select.select([proc.stdout], [], [], 60.0)
            assert ready, "relay did not start"
            port = int(proc.stdout.readline().split()[1].rsplit(":", 1)[1])
            client = UDPClient("127.0.0.1", port)
            rx.settimeout(2.0)
            for i in range(3 * MIN_FRAMES):
                client.send(vmc_bundle(names, [0.3 + 0.2 * np.sin(i / 5), 0.1, 0.6]))
                rx.recv(65536)  # one frame through before the next: none is stale
                time.sleep(0.002)
            out, err = interrupt(proc)
    assert proc.returncode == 0, err
    assert err.count("does not look like raw MediaPipe") == 1 and "tongueOut" in err
