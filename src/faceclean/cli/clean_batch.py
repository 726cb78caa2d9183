"""The batch form of ``faceclean clean`` (several files, or folders, into ``OUTDIR/``).

One progress bar (files) on stderr, one line per file on stdout as it finishes, then a
summary naming each failed file and why; exit 1 when any file failed. Every output is
written atomically, so a failed file leaves nothing behind (nor a folder made for it:
folders the batch made that end empty go once every file has ended, never sooner, as
another worker may be about to write into one).
``--jobs N`` runs N worker processes (``faceclean.workers``: at most one per file and two
per core, said when capped; they die with this process), each cleaning whole files.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from faceclean.batch import Job, is_batch, plan, refuse_links
from faceclean.cli.tasks import Failure, done, summary
from faceclean.errors import FacecleanError

__all__ = ["is_batch", "run"]


def run(args: argparse.Namespace) -> int:
    from concurrent.futures import as_completed

    from tqdm import tqdm

    from faceclean import workers
    from faceclean.channels import ARKIT52
    from faceclean.cli import options
    from faceclean.cli.clean_take import build_cleaner, build_levels

    workers.count(args.jobs, None)  # --jobs 0: refused before anything is read
    if getattr(args, "cluster", None) is not None and (args.jobs != 1 or args.in_place):
        raise FacecleanError(
            "--cluster runs on the cluster's workers into a new folder (a rerun skips what "
            "is done): without --jobs and --in-place"
        )
    if args.fmt is not None:
        raise FacecleanError("a batch keeps each file's format: --format is for one file")
    # bad options fail once, here, not once per file
    choice = options.choice(args)
    build_cleaner(choice, ARKIT52)
    build_levels(args, choice, ARKIT52)
    jobs = plan(args.input, args.output)
    skipped = _earlier(args.input, args.output)
    if not args.in_place:
        from faceclean.io.paths import same_file

        onto = [job for job in jobs if same_file(job.src, job.dst)]
        if onto:
            more = f" (and {len(onto) - 1} more)" if len(onto) > 1 else ""
            raise FacecleanError(
                f"{onto[0].dst} is the input {onto[0].src}{more}: a batch into the input "
                "folder would overwrite raw takes; give another -o folder, or --in-place"
            )
    refuse_links(args.output, [job.dst for job in jobs])  # a link planted in the folder
    n, note = workers.count(args.jobs, len(jobs), "files" if len(jobs) != 1 else "file")
    if note:
        print(note, file=sys.stderr)
    if getattr(args, "cluster", None) is not None:
        return _on_cluster(args, jobs)
    Path(args.output).mkdir(parents=True, exist_ok=True)
    new = _new_folders(jobs)
    failed: list[Failure] = []
    bar = tqdm(total=len(jobs), unit="file", file=sys.stderr, desc="cleaning", leave=False)
    with bar:
        if n == 1:
            for job in jobs:
                done(bar, str(job.src), _clean(args, job), failed, echo=True)
        else:  # workers that die with this process, stopped at once by Ctrl-C
            with workers.Pool(n) as pool:
                futures = {pool.submit(_clean, args, job): job for job in jobs}
                for future in as_completed(futures):
                    done(bar, str(futures[future].src), future.result(), failed, echo=True)
    _tidy(new)
    print(f"cleaned {len(jobs) - len(failed)} of {len(jobs)} files into {args.output}")
    if skipped:  # batch.plan does not walk the output folder (earlier outputs)
        print(f"({skipped} file{'s' * (skipped > 1)} already in {args.output}, inside the "
              "input folder, not cleaned again)")  # fmt: skip
    return summary(failed)


def _on_cluster(args: argparse.Namespace, jobs: list[Job]) -> int:
    """The batch as one Dask task per file (cli/cluster.py); a rerun into the same folder
    with the same options skips the files already cleaned."""
    import os

    from tqdm import tqdm

    from faceclean.cli import cluster

    remote = argparse.Namespace(**vars(args))  # the files a worker reads, absolute
    remote._run = None
    for key in ("method", "model", "preset", "calibration"):
        if (value := getattr(remote, key, None)) and os.path.isfile(value):
            setattr(remote, key, os.path.abspath(value))
    files = [v for k in ("method", "model", "preset", "calibration")
             if (v := getattr(remote, k, None)) and os.path.isabs(v)]  # fmt: skip
    files += [os.path.abspath(i) for i in args.input if os.path.exists(i)]
    out = Path(os.path.abspath(args.output))
    label = {Job(Path(os.path.abspath(j.src)), out / j.dst.relative_to(args.output)): str(j.src)
             for j in jobs}  # fmt: skip
    client = cluster.connect(args.cluster)
    try:
        out.mkdir(parents=True, exist_ok=True)
        cluster.require(client, files, out)
        new = _new_folders(label)
        with cluster.hold(out, {k: getattr(args, k, None) for k in _OPTIONS}) as again:
            todo = [j for j in label if not (again and j.dst.is_file())]
            if len(todo) < len(jobs):
                print(f"{len(jobs) - len(todo)} of {len(jobs)} files already cleaned in "
                      f"{args.output} (an earlier run); {len(todo)} to clean")  # fmt: skip
            failed: list[Failure] = []
            bar = tqdm(total=len(todo), unit="file", file=sys.stderr, desc="cleaning", leave=False)
            with bar:
                tasks = [(remote, j) for j in todo]
                cluster.run(client, _clean, tasks, [label[j] for j in todo], bar, failed, True)
            _tidy(new)
    finally:
        client.close()
    print(f"cleaned {len(todo) - len(failed)} of {len(todo)} files into {args.output}")
    return summary(failed)


# what a folder's outputs depend on: a rerun with other values is refused (cluster.hold)
_OPTIONS = ("method", "model", "tracker", "preset", "params", "calibration", "scale", "compress")


def _clean(args: argparse.Namespace, job: Job) -> tuple[bool, str]:
    """(True, the written line) or (False, why); never raises for a bad file."""
    import os

    from faceclean.cli.clean_take import clean_one

    try:
        job.dst.parent.mkdir(parents=True, exist_ok=True)  # another task's too, maybe
        return True, clean_one(args, str(job.src), str(job.dst), progress=False)
    except FacecleanError as e:
        why = str(e)
    except (OSError, MemoryError) as e:
        why = str(e) or type(e).__name__
    except Exception as e:  # one bad file must not stop the batch
        if os.environ.get("FACECLEAN_DEBUG"):
            raise
        why = f"internal error: {type(e).__name__}: {e}"
    return False, why


def _new_folders(jobs) -> list[Path]:
    """The output folders ``jobs`` write into that are not there yet, deepest first."""
    new: set[Path] = set()
    for job in jobs:
        folder = job.dst.parent
        while folder not in new and not folder.exists():
            new.add(folder)
            folder = folder.parent
    return sorted(new, key=lambda p: len(p.parts), reverse=True)


def _tidy(folders: list[Path]) -> None:
    """Each of ``folders`` (deepest first) that ended empty goes: it was made for files
    that all failed. Only once every task has ended: a file that fails while another
    task is cleaning into the same new folder must not take the folder from under it."""
    import contextlib

    for folder in folders:
        with contextlib.suppress(OSError):  # not empty, or gone: left as it is
            folder.rmdir()


def _earlier(inputs: list[str], out: str) -> int:
    """Animation files already in ``out`` when it lies inside an input folder: the walk
    skips them (a batch's own earlier outputs), and the summary says so."""
    import os

    from faceclean.batch import EXTENSIONS

    o = os.path.realpath(out)
    inside = any(
        os.path.isdir(i) and o != (r := os.path.realpath(i)) and os.path.commonpath([o, r]) == r
        for i in inputs
    )
    if not inside or not os.path.isdir(o):
        return 0
    return sum(Path(f).suffix.lower() in EXTENSIONS for _, _, fs in os.walk(o) for f in fs)
