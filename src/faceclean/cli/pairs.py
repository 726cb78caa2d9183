"""``faceclean pairs``: render takes, track them with MediaPipe, write (tracked, truth) pairs.

Resumable (a finished pair is skipped), sharded (``--shard i/n`` keeps every n-th job of
the same fixed list, so a cluster's array job can spread it), parallel (``--jobs``), with a
progress bar on stderr; failures are listed at the end and do not stop the others.
"""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path

from faceclean.cli.tasks import done, summary
from faceclean.errors import FacecleanError

_LOADING = threading.Lock()  # a cluster worker's threads load its Worker once

MAX_SEED = 2**63 // 100_001  # --seed: every performer's seed (seed * 100000 + k) an int64
HELP = "render faces from known weights, track them with MediaPipe: paired training data"
EPILOG = """examples:
  faceclean pairs --shared --synthetic 20 -o ~/.cache/faceclean/pairs --jobs 2
  faceclean pairs my_takes/ --settings studio,webcam -o pairs/ --shard 3/8
  faceclean train --pairs ~/.cache/faceclean/pairs --out mediapipe.npz"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", nargs="*", help="takes or folders of takes (truth performances)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder of pairs")
    p.add_argument("--shared", action="store_true", help="also the shared real ARKit takes")
    p.add_argument(
        "--synthetic", type=int, default=0, metavar="N", help="N full-range synthetic performers"
    )
    p.add_argument("--seconds", type=float, default=20.0, help="clip length in s (default 20)")
    p.add_argument(
        "--settings",
        default="studio,webcam",
        help="render settings, one drawn per clip: studio, webcam, window (default studio,webcam)",
    )
    p.add_argument(
        "--held-out",
        default="",
        metavar="SETTINGS",
        help="also render every clip in these settings (for evaluation), e.g. window",
    )
    p.add_argument(
        "--rates", default="24,30,30,30,60", help="tracker rates in Hz drawn per clip (24-60)"
    )
    p.add_argument(
        "--webcam-share", type=float, default=0.25, help="share of clips with webcam timing"
    )
    p.add_argument("--seed", type=int, default=0, help="same seed, same jobs and scenes")
    p.add_argument("--shard", default="0/1", metavar="I/N", help="run the I-th of N shards")
    p.add_argument("--jobs", type=int, default=1, metavar="N", help="worker processes")
    p.add_argument(
        "--cluster",
        metavar="ADDRESS",
        help="one task per clip on a running Dask scheduler (tcp://host:8786, or its "
        "--scheduler-file JSON) instead of local workers (docs/SCALE.md)",
    )
    p.add_argument("--head", metavar="NPZ", help="head mesh (default shared ict_full.npz)")
    p.add_argument(
        "--tracker-model", metavar="TASK", help="face_landmarker.task (default ../shared/models)"
    )
    p.add_argument(
        "--rom",
        action="store_true",
        help="also each pair's calibration clip (neutral, then a range of motion) with the same "
        "face and camera: NAME.rom.tracked.csv, NAME.rom.truth.csv (for calibration rows)",
    )
    p.add_argument(
        "--families",
        default="painted",
        help="appearance families, dealt in turn within each source: painted, photo, "
        "dressed, groomed (default painted; docs/MODEL.md)",
    )
    p.add_argument(
        "--portraits",
        nargs="+",
        metavar="PATH",
        help="the photo family's portraits: images, folders, or the sdists docs/DATA.md names "
        "(default ~/.cache/faceclean/portraits, filled by make portraits)",
    )
    p.add_argument(
        "--independent",
        type=int,
        default=0,
        metavar="N",
        help="N performers whose channels move one by one over their whole range",
    )
    p.add_argument(
        "--neutral",
        type=float,
        default=0.0,
        metavar="S",
        help="also hold every scene's face at rest for S seconds (group 'neutral')",
    )
    p.add_argument(
        "--eyes",
        choices=("turn", "still"),
        default="turn",
        help="turn: the eyeballs follow the eyeLook weights (default); still: they look ahead "
        "and the lids alone move (the pairs made before; docs/MODEL.md)",
    )
    p.add_argument("--list", action="store_true", help="print this shard's jobs and stop")


def run(args: argparse.Namespace) -> int:
    from concurrent.futures import as_completed

    from tqdm import tqdm

    from faceclean import workers as pool_of
    from faceclean.synthetic import engine

    pool_of.count(args.jobs, None)  # --jobs 0: refused before any take is read
    if args.cluster is not None and args.jobs != 1:
        raise FacecleanError("--cluster runs on the cluster's workers: without --jobs")

    families = _families(args.families)
    head, model = _files(args)
    worker, usable = None, ()
    if "photo" in families:  # the portraits that fit, before the plan deals them out
        worker = engine.Worker(head, model, _portraits(args.portraits))
        ok, skipped = worker.usable()
        for line in skipped:
            print(f"faceclean: {line}", file=sys.stderr)
        if not ok:
            raise FacecleanError("the photo family has no usable portrait (each is said above)")
        usable = tuple(ok)
    jobs = engine.shard(_plan(args, families, usable), *_shard(args.shard))
    out = Path(args.output)
    if args.list:
        for job in jobs:
            print(job.name, "(done)" if engine.done(job, out) else "")
        return 0
    todo = []  # in plan order, each pair followed by its calibration clip
    for j in jobs:
        todo += [(j, "pair")] if not engine.done(j, out) else []
        todo += [(j, "rom")] if args.rom and not engine.rom_done(j, out) else []
    if out.exists() and not out.is_dir():
        raise FacecleanError(f"output is not a folder: {out}")
    linked = sorted(p for p in out.iterdir() if p.is_symlink()) if out.is_dir() else []
    if linked:  # a link planted there would take a pair's file elsewhere
        raise FacecleanError(f"{linked[0]} is a symbolic link: pairs are written only inside "
                             f"{out} (remove it, or give another -o folder)")  # fmt: skip
    try:  # the output folder before any work (issue 21: outputs are checked at start)
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise FacecleanError(f"cannot make the output folder {out}: {e.strerror or e}") from None
    portraits = [str(p) for p in _portraits(args.portraits)] if usable else []
    # a bad mesh or model file: one line, before any job
    worker = worker or engine.Worker(head, model, portraits)
    workers, note = pool_of.count(args.jobs, len(todo), "pairs to make")
    if note and todo:
        print(note, file=sys.stderr)
    n_rom = sum(kind == "rom" for _, kind in todo)
    made = len(jobs) - (len(todo) - n_rom)
    print(f"{made} of {len(jobs)} pairs already done; {len(todo) - n_rom} to make"
          + (f", and {n_rom} calibration clips" if args.rom else ""))  # fmt: skip
    if args.cluster is not None:
        return _on_cluster(args, todo, (str(head), str(model), portraits))
    failed: list[tuple[str, str]] = []
    bar = tqdm(total=len(todo), unit="pair", file=sys.stderr, desc="pairs", leave=False)
    with bar:
        if workers <= 1 and todo:
            for job, kind in todo:
                done(bar, _label(job, kind), _safe(worker, job, kind, out), failed)
        elif todo:
            del worker  # spawned workers (never a fork of MediaPipe) that die with this process
            init = (str(head), str(model), portraits)
            with pool_of.Pool(workers, initializer=_init, initargs=init) as pool:
                futures = {
                    pool.submit(_job, job, kind, str(out)): _label(job, kind) for job, kind in todo
                }
                for f in as_completed(futures):
                    done(bar, futures[f], f.result(), failed)
    print(f"made {len(todo) - len(failed)} of {len(todo)} in {out}")
    return summary(failed)


def _families(text: str) -> tuple[str, ...]:
    from faceclean.synthetic.scene import FAMILIES

    names = tuple(dict.fromkeys(s.strip() for s in text.split(",") if s.strip()))
    bad = [f for f in names if f not in FAMILIES]
    if not names:
        raise FacecleanError(f"--families names none: give one or more of {', '.join(FAMILIES)}")
    if bad:
        raise FacecleanError(
            f"unknown appearance family {bad[0]!r} (one of: {', '.join(FAMILIES)})"
        )
    return names


def _portraits(given: list[str] | None) -> list[Path]:
    if given:
        return [Path(g) for g in given]
    cache = Path.home() / ".cache" / "faceclean" / "portraits"
    if not cache.is_dir():
        raise FacecleanError(
            f"no portraits in {cache}: run make portraits (or give --portraits PATH)"
        )
    return [cache]


def _plan(args: argparse.Namespace, families: tuple[str, ...] = ("painted",),
          portraits: tuple[str, ...] = ()) -> list:  # fmt: skip
    from faceclean import io, settings
    from faceclean.batch import plan as files_of
    from faceclean.synthetic import engine
    from faceclean.synthetic.scene import SETTINGS

    names = tuple(s.strip() for s in args.settings.split(",") if s.strip())
    held = tuple(s.strip() for s in args.held_out.split(",") if s.strip())
    bad = [s for s in names + held if s not in SETTINGS]
    if bad or not names:
        raise FacecleanError(
            f"unknown render setting {bad[0] if bad else '(none)'!r} "
            f"(one of: {', '.join(SETTINGS)})"
        )
    try:
        rates = tuple(float(r) for r in args.rates.split(","))
    except ValueError:
        raise FacecleanError(f"--rates: expected Hz like 24,30,60, got {args.rates!r}") from None
    if not rates or not all(24.0 <= r <= 60.0 for r in rates):
        raise FacecleanError(f"--rates must lie in 24-60 Hz, got {args.rates!r}")
    if not 0.0 <= args.webcam_share <= 1.0:
        raise FacecleanError(f"--webcam-share must be in [0, 1], got {args.webcam_share}")
    for flag, n in (("--synthetic", args.synthetic), ("--independent", args.independent)):
        if not 0 <= n <= 100_000:
            raise FacecleanError(f"{flag} must be in [0, 100000], got {n}")
    if not 0 <= args.seed < MAX_SEED:  # each performer's own is seed * 100000 + k, < 2**63
        raise FacecleanError(f"--seed must be in [0, {MAX_SEED}), got {args.seed}")
    if not 0.0 <= args.neutral <= 60.0:
        raise FacecleanError(f"--neutral must be in [0, 60] s, got {args.neutral}")
    paths = []
    if args.shared:
        root = settings.takes_dir()
        if root is None:
            raise FacecleanError("--shared: no shared takes folder (set FACECLEAN_DATA)")
        paths += sorted(root.rglob("*.csv"))
    for given in args.input:
        p = Path(given)
        if p.is_dir():
            paths += [j.src for j in files_of([given], "/nonexistent-out")]
        else:
            paths.append(p)
    takes = []
    for p in paths:
        anim = io.load(p)  # an unreadable take: one line, before any work
        takes.append((str(p), Path(p).resolve().parent.name, anim.duration))
    if not takes and args.synthetic == 0 and args.independent == 0:
        raise FacecleanError(
            "nothing to render: give takes, --shared, --synthetic N or --independent N"
        )
    return engine.plan(
        takes, args.synthetic, args.seconds, names, rates, args.seed, args.webcam_share, held,
        families=families, portraits=portraits, independent=args.independent,
        neutral=args.neutral, gaze=args.eyes == "turn",
    )  # fmt: skip


def _shard(text: str) -> tuple[int, int]:
    try:
        i, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise FacecleanError(f"--shard: expected I/N like 0/4, got {text!r}") from None
    if not (n >= 1 and 0 <= i < n):
        raise FacecleanError(f"--shard {text}: need 0 <= I < N")
    return i, n


def _files(args: argparse.Namespace) -> tuple[Path, Path]:
    from faceclean import settings

    head = Path(args.head) if args.head else settings.mesh_file("ict_full.npz")
    model = Path(args.tracker_model) if args.tracker_model else settings.tracker_model()
    if head is None:
        raise FacecleanError("no head mesh: give --head ict_full.npz (or set FACECLEAN_DATA)")
    if model is None:
        raise FacecleanError("no tracker model: give --tracker-model face_landmarker.task")
    return head, model


def _label(job, kind: str) -> str:
    return job.name if kind == "pair" else f"{job.name} (calibration clip)"


def _safe(worker, job, kind: str, out) -> tuple[bool, str]:
    """One task ("pair" or "rom"), its failure as (False, the reason)."""
    try:
        meta = (worker.run if kind == "pair" else worker.run_rom)(job, Path(out))
        return True, f"{job.name}: {meta['frames']} frames, {meta['lost']} lost"
    except FacecleanError as e:
        return False, str(e)
    except (ValueError, RuntimeError, OSError, MemoryError) as e:  # a render or tracking failure
        return False, f"{type(e).__name__}: {' '.join(str(e).split())[:160]}"


def _on_cluster(args: argparse.Namespace, todo: list, files: tuple) -> int:
    """The pairs to make as one Dask task per clip (cli/cluster.py); each worker loads the
    head, the tracker model and the portraits once, from the same paths (shared files)."""
    import os

    from tqdm import tqdm

    from faceclean.cli import cluster

    head, model, portraits = (os.path.abspath(files[0]), os.path.abspath(files[1]),
                              [os.path.abspath(p) for p in files[2]])  # fmt: skip
    out = os.path.abspath(args.output)
    takes = {j.source for j, _ in todo if os.path.isfile(j.source)}
    client = cluster.connect(args.cluster)
    try:
        cluster.require(client, [head, model, *portraits, *map(os.path.abspath, takes)], out)
        failed: list[tuple[str, str]] = []
        with cluster.hold(Path(out), {"command": "pairs"}), tqdm(
            total=len(todo), unit="pair", file=sys.stderr, desc="pairs", leave=False
        ) as bar:  # fmt: skip
            remote = (head, model, portraits, os.getcwd())
            tasks = [(remote, job, kind, out) for job, kind in todo]
            cluster.run(client, _remote, tasks, [_label(j, k) for j, k in todo], bar, failed)
    finally:
        client.close()
    print(f"made {len(todo) - len(failed)} of {len(todo)} in {args.output}")
    return summary(failed)


_WORKER = None
_FILES: tuple | None = None  # what _WORKER was loaded from (a cluster worker's cache)


def _remote(files: tuple, job, kind: str, out: str) -> tuple[bool, str]:
    """One clip on a cluster worker: its Worker loaded on the first task, kept after."""
    global _WORKER, _FILES
    with _LOADING:
        if files != _FILES:
            from faceclean.synthetic import engine

            head, model, portraits, root = files
            _WORKER, _FILES = engine.Worker(head, model, portraits, root), files
        worker = _WORKER
    return _safe(worker, job, kind, out)


def _init(head: str, model: str, portraits: list[str]) -> None:
    global _WORKER
    from faceclean.synthetic import engine

    _WORKER = engine.Worker(head, model, portraits)


def _job(job, kind: str, out: str) -> tuple[bool, str]:
    return _safe(_WORKER, job, kind, out)
