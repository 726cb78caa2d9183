"""`faceclean pairs`: resumable, sharded, parallel, failures listed, nothing half-written."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.settings import mesh_file, tracker_model

pytest.importorskip("numba")
pytest.importorskip("mediapipe")
CLI = [sys.executable, "-m", "faceclean", "pairs"]
FAST = ["--seconds", "1", "--settings", "studio", "--rates", "24", "--webcam-share", "0"]


@pytest.fixture(scope="module", autouse=True)
def shared_files():
    for p in (mesh_file("ict_full.npz"), tracker_model()):
        if p is None or not p.is_file():
            pytest.skip("shared ict_full.npz or face_landmarker.task absent")


def run(*args, **kw):
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, **kw)


@pytest.mark.slow
def test_pairs_are_written_whole_and_a_rerun_skips_them(tmp_path):
    out = tmp_path / "pairs"
    r = run("--synthetic", 2, *FAST, "-o", out, "--jobs", 2)
    assert r.returncode == 0, r.stderr
    metas = sorted(out.glob("*.json"))
    assert len(metas) == 2
    meta = json.loads(metas[0].read_text())
    assert meta["format"] == "faceclean-pair/1" and meta["frames"] == 25
    tracked = io.load(metas[0].with_name(metas[0].stem + ".tracked.csv"))
    truth = io.load(metas[0].with_name(metas[0].stem + ".truth.csv"))
    np.testing.assert_array_equal(tracked.times, truth.times)  # same timestamps
    assert len(tracked.names) == 51 and "tongueOut" in truth.names
    again = run("--synthetic", 2, *FAST, "-o", out)
    assert again.returncode == 0 and "2 of 2 pairs already done; 0 to make" in again.stdout


def test_shards_split_the_same_job_list(tmp_path):
    names = []
    for i in range(2):
        r = run("--synthetic", 3, *FAST, "-o", tmp_path, "--shard", f"{i}/2", "--list")
        assert r.returncode == 0, r.stderr
        names.append(r.stdout.split())
    full = run("--synthetic", 3, *FAST, "-o", tmp_path, "--list").stdout.split()
    assert sorted(names[0] + names[1]) == sorted(full) and not set(names[0]) & set(names[1])
    bad = run("--synthetic", 1, "-o", tmp_path, "--shard", "2/2")
    assert bad.returncode == 2 and "need 0 <= I < N" in bad.stderr


def test_a_failing_take_is_listed_and_the_others_are_made(tmp_path):
    lost = tmp_path / "lost.csv"  # reads fine, but every frame is tracking loss
    io.save(
        Animation(np.arange(30) / 30, np.full((30, 2), np.nan), ("jawOpen", "eyeBlinkLeft")), lost
    )
    r = run(lost, "--synthetic", 1, *FAST, "-o", tmp_path / "out")
    assert r.returncode == 1
    assert "1 failed" in r.stderr and "lost.csv: fewer than 2 frames" in r.stderr
    assert len(list((tmp_path / "out").glob("*.json"))) == 1


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--tracker-model", "{tmp}/no.task"], "no such tracker model file"),
        (["--head", "{tmp}/bad.npz"], "not an ICT head mesh"),
        (["--settings", "moon"], "unknown render setting 'moon'"),
        (["{tmp}/absent.csv"], "no such file"),
        (["--rates", "120"], "24-60 Hz"),
    ],
)
def test_bad_files_and_options_are_one_line(tmp_path, extra, message):
    np.savez(tmp_path / "bad.npz", neutral_vertices=np.zeros((3, 3)))
    args = [a.format(tmp=tmp_path) for a in extra]
    r = run("--synthetic", 1, *FAST, *args, "-o", tmp_path / "out")
    assert r.returncode == 2, r.stderr
    assert message in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_a_killed_run_resumes_without_redoing_finished_pairs(tmp_path):
    out = tmp_path / "out"
    args = [*CLI, "--synthetic", 3, *FAST, "-o", out]
    p = subprocess.Popen(list(map(str, args)), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 240
    while not list(out.glob("*.json")) and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.05)  # polling for the first finished pair, not waiting a fixed time
    p.send_signal(signal.SIGTERM)
    p.communicate(timeout=60)
    done = {m.name for m in out.glob("*.json")}
    assert done and len(done) < 3
    assert not [f for f in os.listdir(out) if f.endswith(".tmp")]  # nothing half-written
    again = run("--synthetic", 3, *FAST, "-o", out)
    assert again.returncode == 0, again.stderr
    assert f"{len(done)} of 3 pairs already done" in again.stdout
    assert done <= {m.name for m in out.glob("*.json")} and len(list(out.glob("*.json"))) == 3


def test_a_pair_whose_json_cannot_be_written_writes_none_of_its_files(tmp_path):
    # a folder under the JSON's name: the two CSVs were written, then the JSON refused
    from faceclean.channels import ARKIT52
    from faceclean.errors import FacecleanError
    from faceclean.synthetic import engine

    (tmp_path / "p.json").mkdir()
    anim = Animation(np.arange(5) / 30, np.zeros((5, 52)), ARKIT52)
    with pytest.raises(FacecleanError, match="p.json"):
        engine.write_pair(tmp_path, "p", anim, anim, {"format": "faceclean-pair/1"})
    assert sorted(q.name for q in tmp_path.iterdir()) == ["p.json"]


def test_a_pair_missing_one_of_its_files_is_made_again_not_counted_done(tmp_path):
    out = tmp_path / "out"
    first = run("--synthetic", 1, *FAST, "-o", out)
    assert first.returncode == 0, first.stderr
    (name,) = [m.name[: -len(".json")] for m in out.glob("*.json")]
    (out / f"{name}.truth.csv").unlink()  # lost since: the JSON alone is no pair
    again = run("--synthetic", 1, *FAST, "-o", out)
    assert again.returncode == 0, again.stderr
    assert "0 of 1 pairs already done" in again.stdout
    assert (out / f"{name}.truth.csv").is_file() and (out / f"{name}.tracked.csv").is_file()


def test_a_range_of_motion_clip_is_done_only_with_both_its_files(tmp_path):
    from faceclean.synthetic import engine

    job = engine.Job("synth:1", "synthetic", 0.0, 2.0, seed=7, setting="studio", rate=24.0,
                     webcam=False)  # fmt: skip
    engine.rom_path(tmp_path, job, "tracked").write_text("time\n0\n")
    assert not engine.rom_done(job, tmp_path)  # its truth lost: made again
    engine.rom_path(tmp_path, job, "truth").write_text("time\n0\n")
    assert engine.rom_done(job, tmp_path)
