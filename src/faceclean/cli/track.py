"""``faceclean track VIDEO -o OUT``: a video (or a camera) to a clean take.

MediaPipe Face Landmarker (VIDEO mode) tracks every frame at the video's own time
(variable frame rate included), the MediaPipe cleaner (``--tracker mediapipe``, the
default here) or the cleaner the options name cleans it, and the take is written in the
format OUT's extension says (Live Link CSV with HeadYaw/HeadPitch/HeadRoll, JSON, NPZ,
glTF/GLB with a head node). A face lost for some frames leaves missing frames. Several
videos (or ``-o OUTDIR/``) run as a batch, ``--jobs N`` at once; ``--keep-raw`` writes the
raw scores beside each take (``take.raw.csv``) to re-clean without re-tracking.
Two faces in view (issue 36): the take is written whole, following the face the one line
names, and the command exits 1 (a batch: every video written, exit 1 if any had two).

Live: ``faceclean track --camera 0 --send vmc://127.0.0.1:39539 [--record take.csv]``
tracks a webcam, stamps each frame at capture, cleans and sends as the relay does;
``--camera FILE`` plays a video file as the camera (for tests: no camera needed).
See docs/TRACK.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from faceclean.cli import options
from faceclean.cli.tasks import summary
from faceclean.errors import FacecleanError

HELP = "track a video (or a webcam) with MediaPipe and write (or send) a clean take"
EXTENSIONS = {"livelink": ".csv", "csv": ".csv", "json": ".json", "npz": ".npz", "gltf": ".glb"}
EPILOG = (
    options.SETTINGS_HELP
    + """\
videos:
  faceclean track clip.mp4 -o clip.csv          Live Link CSV (+ head angles); .json, .npz,
                                                .glb write those formats
  faceclean track a.mp4 b.webm -o out/ --jobs 2  a batch: out/a.csv, out/b.csv
  faceclean track clip.mp4 -o clip.csv --keep-raw  also clip.raw.csv: MediaPipe's raw scores
live:
  faceclean track --camera 0 --send vmc://127.0.0.1:39539 --record take.csv
  faceclean track --camera clip.mp4 --send livelink://127.0.0.1:11111  a file as the camera
"""
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="VIDEO", nargs="*", help="video file(s)")
    p.add_argument("-o", "--output", metavar="OUT", help="take file, or OUTDIR/ for a batch")
    options.add_arguments(p)
    p.set_defaults(tracker="mediapipe")  # what this command's scores are
    p.add_argument(
        "--format",
        dest="fmt",
        choices=tuple(EXTENSIONS),
        help="batch: the format of each take (default livelink: OUTDIR/NAME.csv); one "
        "video: force a format over OUT's extension",
    )
    p.add_argument(
        "--keep-raw", action="store_true", help="also write the raw scores: NAME.raw.csv"
    )
    p.add_argument("--jobs", type=int, default=1, metavar="N", help="batch: N videos at once")
    p.add_argument(
        "--tracker-model", metavar="FILE", help="face_landmarker.task (default: settings)"
    )
    live = p.add_argument_group("live (a camera)")
    live.add_argument(
        "--camera", metavar="N|FILE", help="camera index, or a video file played as a camera"
    )
    live.add_argument("--send", metavar="URL", help="vmc://HOST:PORT or livelink://HOST:PORT")
    live.add_argument("--record", metavar="FILE", help="save the raw scores to FILE (.csv or "
                      ".npz), the cleaned ones beside it: take.csv -> take.clean.csv")  # fmt: skip
    live.add_argument("--stats", type=float, metavar="SECONDS", help="print counters this often")
    live.add_argument("--ui", action="store_true", help="serve the tuning page: the camera "
                      "image beside the two faces, drops counted")  # fmt: skip
    from faceclean.cli import ui

    ui.add_page_arguments(live, "ui-")
    ui.add_nice_argument(live, "the tracking loop")
    ui.add_script_argument(live)


def run(args: argparse.Namespace) -> int:
    if args.camera is not None:
        if args.input or args.output:
            raise FacecleanError("--camera is live: give --send URL, not videos or -o")
        from faceclean.cli import track_live

        return track_live.run(args)
    if args.send or args.record or args.ui or args.stats is not None or args.script:
        raise FacecleanError("--send, --record, --stats, --ui and --script go with --camera")
    if not args.input:
        raise FacecleanError("give a video file (or --camera N --send URL)")
    if not args.output:
        raise FacecleanError("give -o OUT (a take file, or OUTDIR/ for several videos)")
    from faceclean.cli.clean_take import build_cleaner, build_levels

    choice = options.choice(args)  # bad options fail now, before any tracking
    from faceclean.trackers.mediapipe import NAMES

    build_cleaner(choice, NAMES)
    build_levels(args, choice, NAMES)
    out = args.output
    batch = len(args.input) > 1 or out.endswith(("/", "\\")) or Path(out).is_dir()
    if not batch:
        if args.jobs != 1:
            raise FacecleanError("--jobs is for a batch (several videos into OUTDIR/)")
        text, crowded = track_one(args, args.input[0], out, progress=True)
        print(text)
        return 1 if crowded else 0  # two faces: written whole, but said and not 0
    return _batch(args)


def outputs(args: argparse.Namespace, video: str, out: str) -> tuple[str, str | None]:
    """(take path, raw path or None) for one video."""
    raw = None
    if args.keep_raw:
        p = Path(out)
        raw = str(p.with_name(f"{p.stem}.raw.csv"))
    return out, raw


def track_one(
    args: argparse.Namespace, video: str, out: str, progress: bool = False
) -> tuple[str, bool]:
    """Track, clean and write one video: (the line that says what was written, preceded
    by the one line naming the face tracked when several were in view; whether several
    were)."""
    import time

    from faceclean import io
    from faceclean.adaptation import clean_calibrated
    from faceclean.cli.clean_take import build_cleaner, build_levels, clean_with_progress
    from faceclean.filters import rotation
    from faceclean.trackers import face
    from faceclean.trackers.video import check_video_file

    check_video_file(video)  # noted as an input: an output naming it is refused
    out, raw = outputs(args, video, out)
    fmt = args.fmt
    io.check_output(out, fmt, "livelink")
    if raw is not None:
        io.paths.distinct(out, raw)
        io.check_output(raw, "livelink", "livelink")
    model = face.model_path(args.tracker_model)
    started = time.perf_counter()
    said: list[str] = []  # the one line about several faces in view, if any
    if progress:
        from tqdm import tqdm

        bar = tqdm(unit="frame", file=sys.stderr, leave=False, desc=Path(video).name)
        with bar:

            def tick(done: int, total: int) -> None:
                if total and bar.total != total:
                    bar.total = total
                bar.update(done - bar.n)

            anim = face.track_video(video, model, tick, said.append)
    else:
        anim = face.track_video(video, model, on_crowd=said.append)
    tracked = time.perf_counter() - started
    choice = options.choice(args)
    cleaner, what = build_cleaner(choice, anim.names)
    adjust = build_levels(args, choice, anim.names)
    run = (lambda mapped: clean_with_progress(cleaner, mapped)) if progress else None
    cleaned = rotation.clean_pose(clean_calibrated(cleaner, anim, adjust, run), choice.build_pose)
    done, raw_done = io.paths.verb(out), raw is not None and io.paths.verb(raw)
    with io.atomic.together():  # both written, then both renamed: never one new, one old
        io.save(cleaned, out, fmt=fmt)
        if raw is not None:
            io.save(anim, raw, fmt="livelink")
    lost = int((~anim.valid).sum())
    ms = 1000.0 * tracked / max(anim.n_frames, 1)
    text = "".join(f"{video}: {line}\n" for line in said) + (
        f"{done} {out}: {anim.n_frames} frames"
        + (f" ({lost} without a face: missing)" if lost else "")
        + f", {len(anim.names)} channels + head yaw/pitch/roll, cleaned with {what}"
        + f"; tracked in {tracked:.1f} s ({ms:.1f} ms/frame)"
        + (
            f"; raw scores in {raw}" + (" (replaced)" if raw_done == "replaced" else "")
            if raw
            else ""
        )
    )
    return text, bool(said)


def _batch(args: argparse.Namespace) -> int:
    import os
    from concurrent.futures import as_completed

    from tqdm import tqdm

    from faceclean import workers
    from faceclean.batch import refuse_links

    workers.count(args.jobs, None)  # --jobs 0: refused before anything is read
    outdir = Path(args.output)
    if outdir.exists() and not outdir.is_dir():
        raise FacecleanError(f"-o {outdir}: several videos go into a folder (OUTDIR/)")
    ext = EXTENSIONS[args.fmt or "livelink"]
    jobs = [(v, str(outdir / f"{Path(v).stem}{ext}")) for v in args.input]
    seen: dict[str, str] = {}  # every file the batch writes (takes, raw scores): its video
    written: list[str] = []
    for v, o in jobs:
        for path, whose in zip(outputs(args, v, o), (v, f"{v} (its raw scores)"), strict=True):
            if path is None:
                continue
            written.append(path)
            key = os.path.abspath(path)
            if key in seen:
                raise FacecleanError(f"{seen[key]} and {whose} would both write {path}: "
                                     "rename one")  # fmt: skip
            seen[key] = whose
    refuse_links(args.output, written)  # a link planted in the folder would take a file elsewhere
    n, note = workers.count(args.jobs, len(jobs), "videos" if len(jobs) != 1 else "video")
    if note:
        print(note, file=sys.stderr)
    outdir.mkdir(parents=True, exist_ok=True)
    failed: list[tuple[str, str]] = []
    crowded: list[str] = []  # videos written with two faces in view: exit 1
    bar = tqdm(total=len(jobs), unit="video", file=sys.stderr, desc="tracking", leave=False)

    def done(video: str, ok: bool, text: str, crowd: bool = False) -> None:
        bar.write(text if ok else f"FAILED {video}: {text}", file=sys.stdout)
        bar.update(1)
        if not ok:
            failed.append((video, text))
        elif crowd:
            crowded.append(video)

    with bar:
        if n == 1:
            for v, o in jobs:
                done(v, *_job(args, v, o))
        else:
            with workers.Pool(n) as pool:
                futures = {pool.submit(_job, args, v, o): v for v, o in jobs}
                for future in as_completed(futures):
                    done(futures[future], *future.result())
    print(f"tracked {len(jobs) - len(failed)} of {len(jobs)} videos into {outdir}")
    code = summary(failed)
    return 1 if crowded else code


def _job(args: argparse.Namespace, video: str, out: str) -> tuple[bool, str, bool]:
    """(True, the written line, whether two faces were in view) or (False, why, False);
    never raises for a bad video."""
    import os

    from faceclean.io import paths

    try:
        with paths.command():  # in a worker too: this video is protected from its outputs
            return (True, *track_one(args, video, out))
    except FacecleanError as e:
        return False, str(e), False
    except (OSError, MemoryError) as e:
        return False, str(e) or type(e).__name__, False
    except Exception as e:  # one bad video must not stop the batch
        if os.environ.get("FACECLEAN_DEBUG"):
            raise
        return False, f"internal error: {type(e).__name__}: {e}", False
