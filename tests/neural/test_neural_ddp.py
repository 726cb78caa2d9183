"""The train command runs data-parallel under torchrun: 2 local CPU processes (gloo)."""

from __future__ import annotations

import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from helpers import free_port

from faceclean.settings import takes_dir  # noqa: E402

TORCHRUN = Path(sys.executable).with_name("torchrun")

# The train command (faceclean.neural.train.main, as `torchrun -m` runs it); each rank
# then writes its final weights so that the test can compare them.
SCRIPT = textwrap.dedent(
    """
    import os, sys
    import numpy as np
    import faceclean.neural.train as tr
    from faceclean.neural import checkpoint

    held = {}
    real_wrap = tr.distributed.wrap

    def wrap(model, device):  # keep this rank's model to compare it afterwards
        held["model"] = model
        return real_wrap(model, device)

    tr.distributed.wrap = wrap
    out = sys.argv[1]
    rc = tr.main(["--arch", "lstm", "--val-sources", "jmtechart", "--epochs", "1", "--batch", "2",
                  "--hidden", "8", "--layers", "1", "--max-batches", "2", "--seed", "5",
                  "--quiet", "--out", out])
    rank = int(os.environ["RANK"])
    np.savez(out + f".rank{rank}.npz", **checkpoint.arrays(held["model"]))
    sys.stdout.write(f"rank {rank} world {os.environ['WORLD_SIZE']} rc {rc}\\n")  # one write
    """
)


@pytest.mark.skipif(takes_dir() is None, reason="shared data arkit_takes/ absent")
@pytest.mark.skipif(not TORCHRUN.exists(), reason="torchrun not installed beside python")
@pytest.mark.slow
def test_two_process_training_keeps_ranks_identical(tmp_path):
    script = tmp_path / "ddp_run.py"
    script.write_text(SCRIPT)
    out = tmp_path / "m.npz"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "FACECLEAN_DATA": str(_two_sources(tmp_path))}
    cmd = [
        str(TORCHRUN), "--nproc_per_node", "2", "--master_addr", "127.0.0.1",
        "--master_port", str(free_port(socket.SOCK_STREAM)), str(script), str(out),
    ]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=240)
    # a rank's own last words come before torchrun's summary, which alone fills the tail
    why = [ln for ln in proc.stderr.splitlines()
           if any(w in ln for w in ("Error", "error", "terminate", "what()", "Abort"))]  # fmt: skip
    assert proc.returncode == 0, "\n".join([*why[:30], "...", proc.stderr[-1500:]])
    # two processes share stdout: check the facts, not the interleaving
    assert proc.stdout.count("world 2 rc 0") == 2
    assert "rank 0" in proc.stdout and "rank 1" in proc.stdout
    r0 = np.load(f"{out}.rank0.npz")
    r1 = np.load(f"{out}.rank1.npz")
    assert set(r0.files) == set(r1.files)
    for k in r0.files:
        assert np.array_equal(r0[k], r1[k]), k
    assert "2 process(es)" in proc.stderr
    written = np.load(out)  # rank 0 wrote the model, and it is the trained one
    assert np.array_equal(written["head.w"], r0["head.w"])


def _two_sources(tmp_path: Path) -> Path:
    """A data folder of two shared sources' takes (copies in the test's temporary folder:
    the take reader follows no link) and the meshes: the held-out source and one to train
    on, so that the ranks load two takes, not every shared one."""
    root = tmp_path / "data"
    for source in ("jmtechart", "sentien"):
        (root / "arkit_takes" / source).mkdir(parents=True)
        for take in (takes_dir() / source).glob("*.csv"):
            shutil.copyfile(take, root / "arkit_takes" / source / take.name)
    (root / "meshes").symlink_to(takes_dir().parent / "meshes")  # the loss's face mesh
    return root


def _ranks(agent: int) -> list[int]:
    """The python processes torchrun's agent started (its children, from /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) == agent and b"python" in (d / "cmdline").read_bytes():
                out.append(int(d.name))
        except (OSError, IndexError, ValueError):
            continue
    return out


def _running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")  # a zombie is gone (the container's init may not reap)


def _until(condition, deadline: float) -> bool:
    end = time.monotonic() + deadline
    while not condition() and time.monotonic() < end:
        time.sleep(0.1)
    return condition()


@pytest.mark.skipif(takes_dir() is None, reason="shared data arkit_takes/ absent")
@pytest.mark.skipif(not TORCHRUN.exists(), reason="torchrun not installed beside python")
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
@pytest.mark.slow
def test_ranks_die_when_torchrun_is_killed(tmp_path):
    """SIGKILL to torchrun's agent mid-training: both ranks stop (faceclean.workers
    die_with_parent in distributed.setup), polled up to a deadline, not left training."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "FACECLEAN_DATA": str(_two_sources(tmp_path))}
    cmd = [
        str(TORCHRUN), "--nproc_per_node", "2", "--master_addr", "127.0.0.1",
        "--master_port", str(free_port(socket.SOCK_STREAM)), "-m", "faceclean.neural.train",
        "--arch", "lstm", "--val-sources", "jmtechart", "--epochs", "1000", "--batch", "2",
        "--hidden", "8", "--layers", "1", "--quiet", "--out", str(tmp_path / "m.npz"),
    ]  # fmt: skip
    agent = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    ranks: list[int] = []
    try:
        seen = b""
        end = time.monotonic() + 240
        while b"process(es)" not in seen and time.monotonic() < end:  # rank 0 has started
            ready, _, _ = select.select([agent.stderr], [], [], 1.0)
            if ready:
                chunk = os.read(agent.stderr.fileno(), 4096)
                if not chunk:
                    break
                seen += chunk
        assert b"process(es)" in seen, seen.decode(errors="replace")[-1500:]
        ranks = _ranks(agent.pid)
        assert len(ranks) == 2, ranks
        agent.kill()  # SIGKILL: the agent forwards nothing
        agent.wait(timeout=60)
        assert _until(lambda: not any(map(_running, ranks)), 60.0), [
            p for p in ranks if _running(p)
        ]
    finally:
        for p in ranks:
            if _running(p):
                os.kill(p, signal.SIGKILL)
        if agent.poll() is None:
            agent.kill()
            agent.wait()
