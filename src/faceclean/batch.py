"""Batch planning: which files a batch clean reads and where each one goes.

``plan(inputs, outdir)``: a folder input is walked recursively for files whose extension
``faceclean.io`` reads (hidden files and folders, and the output folder when it lies
inside the input, are skipped); each keeps its path relative to that folder. A file input
goes to ``outdir / name``. Two inputs that would write one output are refused up front.
``refuse_links(outdir, outputs)``: a symbolic link planted in the output folder would
take a batch's file elsewhere (over a file outside it): refused before any work.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from faceclean.errors import FacecleanError
from faceclean.io import EXTENSIONS


@dataclass(frozen=True)
class Job:
    src: Path
    dst: Path


def is_batch(inputs: list[str], output: str) -> bool:
    """Several inputs, a folder input, or an output spelled as a folder (``OUT/``). One
    file into an existing folder without the slash stays refused (the folder is not a
    file), so a typo never scatters outputs."""
    return len(inputs) > 1 or Path(inputs[0]).is_dir() or output.endswith(("/", os.sep))


def plan(inputs: list[str], outdir: str | os.PathLike) -> list[Job]:
    """One Job per input file, in input order (a folder's files sorted)."""
    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise FacecleanError(f"batch output must be a folder, and {out} is a file")
    slash = os.fspath(outdir).endswith(("/", os.sep))  # "-o x.csv/" is a folder, as asked
    if not out.exists() and not slash and out.suffix.lower() in EXTENSIONS:  # -o name.csv
        folder = any(Path(i).is_dir() for i in inputs)
        what = "a folder input writes" if folder else "several inputs write"
        raise FacecleanError(
            f"-o {outdir}: {what} a folder of files, and {out.name} names a file; "
            f"give a folder (-o {out.with_suffix('')}/)"
        )
    jobs: list[Job] = []
    for given in inputs:
        root = Path(given)
        if root.is_dir():
            found = list(_walk(root, out))
            if not found:
                raise FacecleanError(
                    f"{root}: no animation files ({', '.join(sorted(EXTENSIONS))}) in it"
                )
            jobs += [Job(f, out / f.relative_to(root)) for f in found]
        else:  # a missing or unreadable file fails as its own job, with its reason
            jobs.append(Job(root, out / root.name))
    seen: dict[Path, Path] = {}
    for job in jobs:
        key = Path(os.path.abspath(job.dst))
        if key in seen:
            raise FacecleanError(f"{seen[key]} and {job.src} would both write {job.dst}")
        seen[key] = job.src
    return jobs


def through_link(root: str | os.PathLike, dst: str | os.PathLike) -> Path | None:
    """The first symbolic link on the way from the output folder ``root`` to ``dst``."""
    try:
        parts = Path(dst).relative_to(root).parts
    except ValueError:
        return None
    at = Path(root)
    for part in parts:
        at = at / part
        if at.is_symlink():
            return at
    return None


def refuse_links(root: str | os.PathLike, outputs) -> None:
    """Refuse, in one line, a batch whose ``outputs`` (paths under the output folder
    ``root``) go through a symbolic link: a batch writes only inside its folder."""
    linked = [link for dst in outputs if (link := through_link(root, dst))]
    if linked:
        raise FacecleanError(
            f"{linked[0]} is a symbolic link: a batch writes only inside {os.fspath(root)} "
            "(remove it, or give another -o folder)"
        )


def _walk(root: Path, out: Path):
    skip = os.path.abspath(out) if os.path.abspath(out) != os.path.abspath(root) else None
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(
            d
            for d in dirs
            if not d.startswith(".") and os.path.abspath(os.path.join(folder, d)) != skip
        )
        for name in sorted(files):
            if not name.startswith(".") and Path(name).suffix.lower() in EXTENSIONS:
                yield Path(folder) / name
