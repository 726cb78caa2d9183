"""`clean --cluster` and `pairs --cluster` on a real Dask cluster over loopback.

A LocalCluster of two worker processes (each with its nanny) stands for a studio's
cluster: the batch's outputs must be the local batch's, byte for byte; a failing file is
named and the others finish; a worker killed mid-job costs nothing but its task's rerun;
a rerun resumes; an unreachable address, a missing shared file and a folder another job
is writing are refused on one line.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.datasets.performer import perform

distributed = pytest.importorskip("distributed")

CLI = [sys.executable, "-m", "faceclean"]
EMA = ("--method", "ema")


def _cluster():
    return distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # no fixed port: another cluster may hold 8787
        silence_logs=50,
    )


@pytest.fixture(scope="module")
def scheduler():
    with _cluster() as cluster:
        yield cluster.scheduler_address


def run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=300)


def _takes(root):
    """Four takes in three formats and a nested folder, and one broken file."""
    (root / "sub" / "deeper").mkdir(parents=True)
    io.save(perform(2.0, 1, fps=60.0), root / "a.csv", fmt="livelink")
    io.save(perform(2.0, 2, fps=60.0), root / "sub" / "b.npz")
    io.save(perform(2.0, 3, fps=60.0), root / "sub" / "deeper" / "c.csv", fmt="csv")
    io.save(perform(3.0, 4, fps=30.0), root / "sub" / "d.json")
    good = (root / "a.csv").read_text().splitlines()
    bad = good[:5] + ["garbage,row,that,is,not,a,frame"] + good[5:]
    (root / "sub" / "broken.csv").write_text("\n".join(bad) + "\n")


def _files(folder) -> dict[str, bytes]:
    """Every output, by relative path (the cluster's hidden lock file aside)."""
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and not p.name.startswith(".")
    }


def test_a_cluster_batch_writes_the_local_batch_and_names_the_failure(tmp_path, scheduler):
    src = tmp_path / "takes"
    _takes(src)
    local = run("clean", src, "-o", f"{tmp_path / 'local'}/", *EMA)
    far = run("clean", src, "-o", f"{tmp_path / 'far'}/", *EMA, "--cluster", scheduler)
    assert local.returncode == far.returncode == 1, far.stderr
    assert "FAILED" in far.stdout and "broken.csv line 6" in far.stdout
    assert "1 failed" in far.stderr and "broken.csv" in far.stderr
    assert "cleaned 4 of 5 files" in far.stdout
    made = _files(tmp_path / "far")
    assert sorted(made) == ["a.csv", "sub/b.npz", "sub/d.json", "sub/deeper/c.csv"]
    assert made == _files(tmp_path / "local")  # byte for byte
    with distributed.Client(scheduler, set_as_default=False) as client:  # the house rule
        assert not any(client.run(eval, "'torch' in __import__('sys').modules").values())


def test_a_rerun_resumes_and_other_options_are_refused(tmp_path, scheduler):
    src, out = tmp_path / "takes", tmp_path / "out"
    _takes(src)
    assert run("clean", src, "-o", out, *EMA, "--cluster", scheduler).returncode == 1
    first = _files(out)
    (out / "sub" / "b.npz").unlink()  # as if its worker had been lost with the client
    again = run("clean", src, "-o", out, *EMA, "--cluster", scheduler)
    assert again.returncode == 1  # the broken file, tried again and failed again
    assert "3 of 5 files already cleaned" in again.stdout and "2 to clean" in again.stdout
    assert _files(out) == first
    other = run("clean", src, "-o", out, "--method", "one-euro", "--cluster", scheduler)
    assert other.returncode == 2 and other.stderr.count("\n") == 1
    assert "holds the outputs of another run" in other.stderr
    assert _files(out) == first


def test_a_scheduler_file_names_the_cluster(tmp_path, scheduler):
    src = tmp_path / "takes"
    _takes(src)
    (src / "sub" / "broken.csv").unlink()
    # what ``dask scheduler --scheduler-file`` writes, of which a client reads the address
    # (Client.write_scheduler_file itself can fail to encode a busy scheduler's identity)
    with distributed.Client(scheduler, set_as_default=False) as client:
        info = {"type": "Scheduler", "id": client.scheduler_info()["id"], "address": scheduler}
    (tmp_path / "scheduler.json").write_text(json.dumps(info))
    r = run("clean", src, "-o", tmp_path / "out", *EMA, "--cluster", tmp_path / "scheduler.json")
    assert r.returncode == 0, r.stderr
    assert "cleaned 4 of 4 files" in r.stdout


@pytest.mark.timeout(600)
def test_a_worker_killed_mid_job_costs_only_its_task(tmp_path):
    src = tmp_path / "takes"
    _takes(src)
    for k in range(8):  # more files than workers: work left when the worker dies
        io.save(perform(20.0, 10 + k, fps=60.0), src / f"more{k}.csv", fmt="livelink")
    assert run("clean", src, "-o", tmp_path / "local", *EMA).returncode == 1
    with _cluster() as cluster, distributed.Client(cluster, set_as_default=False) as client:
        victim = sorted(client.run(os.getpid).values())[0]
        job = subprocess.Popen(
            [*CLI, "clean", str(src), "-o", str(tmp_path / "far"), *EMA,
             "--cluster", cluster.scheduler_address],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},  # each line as it is printed
        )  # fmt: skip
        try:
            start = job.stdout.readline()  # said as the tasks are submitted: each worker
            assert "13 tasks on 2 workers" in start, start  # is handed its first one now
            os.kill(victim, signal.SIGKILL)
            out, err = job.communicate(timeout=300)
        finally:
            if job.poll() is None:
                job.kill()
    assert job.returncode == 1, err
    assert "cleaned 12 of 13 files" in out and err.count("bad timecode") == 1
    assert _files(tmp_path / "far") == _files(tmp_path / "local")  # none half-written


def _refused_port() -> int:
    with socket.socket() as s:  # bound, never listening: a connection is refused at once
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_address_is_one_line_and_nothing_is_written(tmp_path):
    src = tmp_path / "takes"
    _takes(src)
    for address in (f"tcp://127.0.0.1:{_refused_port()}", "nonsense::", "udp://x:1"):
        r = run("clean", src, "-o", tmp_path / "out", *EMA, "--cluster", address)
        assert r.returncode == 2, r.stderr
        assert r.stderr.count("\n") == 1 and r.stderr.startswith("faceclean: --cluster")
        assert not (tmp_path / "out").exists()


def test_something_else_on_the_port_is_not_taken_for_a_scheduler(tmp_path):
    src = tmp_path / "takes"
    _takes(src)
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        job = subprocess.Popen(
            [*CLI, "clean", str(src), "-o", str(tmp_path / "out"), *EMA,
             "--cluster", f"127.0.0.1:{port}"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        for _ in range(2):  # the port tried, then asked who it is
            conn, _ = server.accept()
            with conn:
                conn.sendall(b"HTTP/1.1 400 Bad Request\r\n\r\n")
        out, err = job.communicate(timeout=60)
    assert job.returncode == 2 and err.count("\n") == 1, err
    assert "not a Dask scheduler" in err


def test_workers_without_a_shared_file_are_refused_before_any_task(tmp_path, scheduler):
    from faceclean.cli import cluster
    from faceclean.errors import FacecleanError

    with distributed.Client(scheduler, set_as_default=False) as client:
        cluster.require(client, [__file__], tmp_path)  # what they see passes
        with pytest.raises(FacecleanError, match=r"cannot see /nowhere/ict_full\.npz"):
            cluster.require(client, [__file__, "/nowhere/ict_full.npz"], tmp_path)
        with pytest.raises(FacecleanError, match="cannot write in the output folder"):
            cluster.require(client, [__file__], tmp_path / "not-made")


def test_a_folder_another_job_is_writing_is_refused(tmp_path, scheduler):
    from faceclean.cli import cluster

    src, out = tmp_path / "takes", tmp_path / "out"
    _takes(src)
    out.mkdir()
    with cluster.hold(out, {"command": "pairs"}):  # a running job's lock
        r = run("clean", src, "-o", out, *EMA, "--cluster", scheduler)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "being written by another running job" in r.stderr
    assert _files(out) == {}


def test_cluster_options_that_do_not_fit_are_refused(tmp_path, scheduler):
    src = tmp_path / "takes"
    _takes(src)
    for extra, words in (
        (["--jobs", "2"], "without --jobs and --in-place"),
        (["--in-place"], "without --jobs and --in-place"),
    ):
        r = run("clean", src, "-o", tmp_path / "out", *EMA, "--cluster", scheduler, *extra)
        assert r.returncode == 2 and words in r.stderr
    one = run("clean", src / "a.csv", "-o", tmp_path / "a.csv", "--cluster", scheduler)
    assert one.returncode == 2 and "--cluster is for a batch" in one.stderr


@pytest.mark.slow
def test_pairs_on_the_cluster_are_the_local_pairs(tmp_path, scheduler):
    pytest.importorskip("mediapipe")
    from faceclean.settings import mesh_file, tracker_model

    for p in (mesh_file("ict_full.npz"), tracker_model()):
        if p is None or not p.is_file():
            pytest.skip("shared ict_full.npz or face_landmarker.task absent")
    take = tmp_path / "take.csv"
    io.save(perform(2.0, 5, fps=60.0), take, fmt="csv")
    lost = tmp_path / "lost.csv"  # reads fine, but every frame is tracking loss
    io.save(Animation(np.arange(30) / 30, np.full((30, 1), np.nan), ("jawOpen",)), lost)
    fast = ["--seconds", 1, "--settings", "studio", "--rates", 24, "--webcam-share", 0]
    local = run("pairs", take, lost, "--synthetic", 1, *fast, "-o", tmp_path / "local")
    far = run("pairs", take, lost, "--synthetic", 1, *fast, "-o", tmp_path / "far",
              "--cluster", scheduler)  # fmt: skip
    assert local.returncode == far.returncode == 1, far.stderr
    assert "lost.csv: fewer than 2 frames" in far.stderr and "made 3 of 4" in far.stdout
    assert _files(tmp_path / "far") == _files(tmp_path / "local")
    assert len(_files(tmp_path / "far")) == 9
    again = run("pairs", take, lost, "--synthetic", 1, *fast, "-o", tmp_path / "far",
                "--cluster", scheduler)  # fmt: skip
    assert "3 of 4 pairs already done; 1 to make" in again.stdout
