"""Batch tasks on a running Dask cluster: ``clean FOLDER -o OUT --cluster ADDRESS`` and
``pairs ... --cluster ADDRESS`` (docs/SCALE.md).

The cluster is Dask's (``distributed``, the ``cluster`` extra; docs/ARCHITECTURE.md says
why). ADDRESS is a scheduler's address (``tcp://host:8786``, ``host:8786``) or the JSON
file ``dask scheduler --scheduler-file`` writes (a Slurm allocation's usual hand-over).

- ``connect(address)``: a client, or one line (FacecleanError) when nothing answers there,
  within about ``CONNECT_S`` s, or when no worker joins in that time.
- ``require(client, files, folder)``: every worker must see the inputs, the shared data
  and models, and be able to write the output folder; the first one missing is named, on
  one line, before any task runs. The work runs where the files are: nothing is shipped
  but the task's arguments (a path, a job record) and the results (a line of text).
- ``hold(folder, what)``: the output folder, locked (``flock``) for the whole run: a
  second job writing it is refused; the lock file remembers ``what`` made the folder (a
  rerun with other options is refused, never mixed in); yields whether an earlier run
  did (its finished outputs then stand: the rerun resumes).
- ``run(client, fn, tasks, labels, bar, failed, echo)``: a line saying how many tasks go
  to how many workers, then one Dask task per item, each its own ``fn(*item)`` -> (ok,
  line or why); results come back as they finish, through
  ``cli.tasks.done`` (the local batch's progress bar, lines and failure list). A worker
  lost mid-task costs that task a rerun elsewhere (Dask reschedules it; after
  ``allowed-failures`` losses it fails alone, named in the summary). Ctrl-C cancels what
  is left.

Outputs are written by the workers as locally (atomically, the same names), so a lost
worker leaves at most a hidden temporary file, never a half-written output.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from faceclean.cli.tasks import Failure, done
from faceclean.errors import FacecleanError

CONNECT_S = 10.0  # s to reach the scheduler, and again for a first worker to join
ANSWER_S = 60.0  # s for every worker to say what it sees (``require``)
PORT = 8786  # Dask's scheduler port, when ADDRESS gives none
LOCK = ".faceclean.lock"  # in the output folder: held while a cluster job writes it
INSTALL = "pip install 'faceclean[cluster]'"


def connect(address: str):
    """A ``distributed.Client`` on ``address``, with at least one worker."""
    try:
        import distributed
    except ImportError:
        raise FacecleanError(f"--cluster needs Dask's distributed: {INSTALL}") from None
    _quiet()
    file = Path(address)
    if address.endswith(".json") or file.is_file():
        if not file.is_file():
            raise FacecleanError(f"--cluster {address}: no such scheduler file")
        target = {"scheduler_file": str(file)}
        try:
            address = json.loads(file.read_text())["address"]
        except (OSError, ValueError, KeyError, TypeError):
            raise FacecleanError(f"--cluster {file}: not a Dask scheduler file") from None
    else:
        target = {"address": address}
    _probe(address)
    try:
        client = distributed.Client(**target, timeout=CONNECT_S, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as e:
        raise FacecleanError(f"--cluster {address}: {_reason(e)}") from None
    try:
        client.wait_for_workers(1, timeout=CONNECT_S)
    except (OSError, TimeoutError):
        client.close()
        raise FacecleanError(
            f"--cluster {address}: the scheduler has no workers (none joined in "
            f"{CONNECT_S:g} s): start some with 'dask worker {address}'"
        ) from None
    return client


def _probe(address: str) -> None:
    """The scheduler asked who it is, once, before a client is made: a wrong host or port
    fails at once with why (a client would retry for ``CONNECT_S`` s, say only that it
    timed out, and complain again at exit), and so does a port where something else
    answers."""
    import asyncio

    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port

    try:
        scheme, location = parse_address(address)
        if scheme in ("tcp", "tls"):
            host, port = parse_host_port(location, PORT)
    except ValueError as e:
        raise FacecleanError(f"--cluster {address}: {e}") from None
    try:
        if scheme in ("tcp", "tls"):
            socket.create_connection((host, port), timeout=CONNECT_S).close()
        who = asyncio.run(asyncio.wait_for(_identity(address), CONNECT_S))
    except (OSError, TimeoutError) as e:
        raise FacecleanError(
            f"--cluster {address}: no scheduler answers there ({_reason(e)})"
        ) from None
    except MemoryError:  # a stranger's first bytes read as a frame's length
        who = {}
    except Exception as e:  # bytes that are not Dask's protocol, an unknown scheme
        raise FacecleanError(f"--cluster {address}: not a Dask scheduler ({_reason(e)})") from None
    if not isinstance(who, dict) or who.get("type") != "Scheduler":
        raise FacecleanError(f"--cluster {address}: something answers there, not a Dask scheduler")


async def _identity(address: str):
    from distributed.core import rpc

    r = rpc(address, timeout=CONNECT_S)
    try:
        return await r.identity()
    finally:
        await r.close_rpc()


def _reason(e: BaseException) -> str:
    return (getattr(e, "strerror", None) or str(e) or type(e).__name__).splitlines()[0]


def _quiet() -> None:
    """Dask's own log lines (a worker lost, a retried connection) off this terminal: the
    command says what happened itself."""
    import logging

    for name in ("distributed", "tornado"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def require(client, files: Sequence[str | os.PathLike], folder: str | os.PathLike) -> None:
    """Every worker sees ``files`` and may write in ``folder`` (absolute paths), and runs
    this faceclean; else one line naming the first gap, before any task runs."""
    import threading

    import faceclean

    wanted = [os.fspath(f) for f in files]
    answers: list = []

    def ask() -> None:  # a stalled worker (stopped, swapping) would hold client.run forever
        try:
            answers.append(client.run(_look, wanted, os.fspath(folder), on_error="return"))
        except Exception as e:
            answers.append(e)

    asking = threading.Thread(target=ask, daemon=True, name="cluster-require")
    asking.start()
    asking.join(ANSWER_S)
    if not answers or isinstance(answers[0], Exception):
        why = f"not in {ANSWER_S:g} s" if not answers else _reason(answers[0])
        raise FacecleanError(f"--cluster: the workers did not all answer ({why})")
    seen = answers[0]
    for worker, answer in sorted(seen.items()):
        if isinstance(answer, BaseException):  # faceclean not importable there, most often
            raise FacecleanError(
                f"--cluster: worker {worker} cannot run faceclean ({_reason(answer)}): "
                f"install it there ({INSTALL})"
            )
        version, gap = answer
        if version != faceclean.__version__:
            raise FacecleanError(
                f"--cluster: worker {worker} runs faceclean {version}, this is "
                f"{faceclean.__version__}: install the same on every worker"
            )
        if gap is not None:
            raise FacecleanError(f"--cluster: worker {worker} {gap}")


def _look(files: list[str], folder: str) -> tuple[str, str | None]:
    """On a worker: (its faceclean version, the first file it lacks, or None)."""
    import faceclean

    for f in files:
        if not os.path.exists(f):
            return faceclean.__version__, f"cannot see {f} (the shared files must be there)"
    if not (os.path.isdir(folder) and os.access(folder, os.W_OK | os.X_OK)):
        return faceclean.__version__, f"cannot write in the output folder {folder}"
    return faceclean.__version__, None


@contextlib.contextmanager
def hold(folder: Path, what: dict) -> Iterator[bool]:
    """The output folder's lock for this run; ``what`` made it (a rerun must match).
    Yields whether an earlier run with the same ``what`` wrote there (its outputs stand)."""
    import fcntl

    fd = os.open(folder / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise FacecleanError(
                f"{folder} is being written by another running job: wait for it to end, "
                "or give another output folder"
            ) from None
        except OSError as e:  # a file system without locks (an NFS mount without lockd)
            print(f"faceclean: {folder} cannot be locked ({_reason(e)}): a second job into "
                  "it would not be refused", file=sys.stderr)  # fmt: skip
        with os.fdopen(os.dup(fd), "r+") as f:
            before = f.read()
            mine = json.dumps(what, sort_keys=True)
            if before.strip() and before.strip() != mine:
                raise FacecleanError(
                    f"{folder} holds the outputs of another run ({_said(before)}): rerun it "
                    "with the same options to resume, or give another output folder"
                )
            f.seek(0)
            f.truncate()
            f.write(mine + "\n")
        yield bool(before.strip())
    finally:
        os.close(fd)  # the lock goes with it


def _said(text: str) -> str:
    try:
        made = json.loads(text)
        return ", ".join(f"{k} {v}" for k, v in sorted(made.items()) if v not in (None, [], ""))
    except (ValueError, AttributeError):
        return "an unreadable record"


def run(
    client,
    fn: Callable[..., tuple[bool, str]],
    tasks: Sequence[tuple],
    labels: Sequence[str],
    bar,
    failed: list[Failure],
    echo: bool = False,
) -> None:
    """``fn(*task)`` for every task on the cluster, each result through ``tasks.done``."""
    from distributed import as_completed

    n = len(client.scheduler_info(n_workers=-1)["workers"])
    print(f"{len(tasks)} task{'s' * (len(tasks) != 1)} on {n} worker{'s' * (n != 1)} at "
          f"{client.scheduler.address}", flush=True)  # fmt: skip
    futures = {}
    try:
        for task, label in zip(tasks, labels, strict=True):
            futures[client.submit(fn, *task, pure=False)] = label
        for future in as_completed(futures, loop=client.loop):
            done(bar, futures[future], _result(future), failed, echo=echo)
    finally:  # an error or Ctrl-C here: nothing left running for this client
        left = [f for f in futures if not f.done()]
        if left:
            with contextlib.suppress(Exception):
                client.cancel(left)


def _result(future) -> tuple[bool, str]:
    """The task's (ok, line), or (False, why) when the task itself did not finish."""
    try:
        return future.result()
    except Exception as e:
        kind = type(e).__name__
        if kind == "KilledWorker":  # lost with its worker more than allowed-failures times
            return False, "its worker was lost each time it ran (KilledWorker)"
        return False, f"internal error on the cluster: {kind}: {_reason(e)}"
