"""``faceclean clean IN -o OUT``: clean a file with one cleaner and write it back.

Batch: ``faceclean clean A.csv B.csv -o OUTDIR/`` or ``faceclean clean FOLDER -o OUTDIR/``
(recursing; each file keeps its relative path and its format) with one progress bar, a
line per file and a summary of what failed and why; exit 1 when any file failed (the
others are written, a failed one leaves nothing). ``--jobs N`` cleans N files at once.

The cleaner: ``--method``/``--model``/``--preset`` and ``--set`` (faceclean.resolve;
``--help`` lists the forms). Levels (before the cleaner, faceclean.adjust):
``--calibration calib.json`` (from ``faceclean calibrate``) and ``--set PATTERN.KEY=VALUE``
with KEY gain, offset, curve, clamp or off, on a channel name, a glob or a group:
``--set 'eyeBlink*.gain=1.2' --set tongueOut.off --set jawOpen.clamp=0,0.8``.

The output format follows OUT's extension (``--format`` forces one); a ``.csv`` out of a
Live Link Face CSV stays Live Link, with only the blendshape values changed. Every
output replaces its file atomically once complete. A causal cleaner on a Live Link or
plain CSV written to the same format streams the file in blocks (constant memory,
faceclean.io.stream); anything else is read whole. Head and eye angles (a Live Link
file's 9 angle columns, ``meta["pose"]``) are cleaned by the rotation filter
(filters/rotation.py, its tuned preset; ``--set head.min_cutoff=0.5``, ``eyes.beta=...``).

A raw take is never replaced by accident: an OUT that is IN (``./IN``, a symlink to it,
a hard link of it: the same file, ``os.path.samefile``) is refused unless ``--in-place``
is given, for one file and for a batch into the input folder; ``clean IN --in-place``
(no ``-o``) replaces IN. A folder input needs a folder output, never ``-o name.csv``.
"""

from __future__ import annotations

import argparse

from faceclean.cli import options

HELP = "clean an animation file (Live Link CSV, CSV, JSON, NPZ, glTF/GLB)"
EPILOG = (
    options.SETTINGS_HELP
    + """\
batch cleaning:
  faceclean clean a.csv b.csv -o OUTDIR/      several files into a folder
  faceclean clean takes/ -o cleaned/ --jobs 2  a folder, recursing: same relative paths and
                                              formats; a line per file, a summary of what
                                              failed and why, exit 1 if any file failed
  faceclean clean takes/ -o cleaned/ --cluster tcp://host:8786
                                              the same on a Dask cluster (docs/SCALE.md)
per-channel levels (before the cleaner; y = clip(sign(u)|u|^curve, lo, hi),
u = gain (x - offset); by channel name, glob or group):
  --set 'eyeBlink*.gain=1.2' --set tongueOut.off --set jawOpen.clamp=0,0.8
  --calibration calib.json                    from 'faceclean calibrate' (--set goes on top)
"""
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="IN", nargs="+", help="animation file(s) or folder(s)")
    p.add_argument(
        "-o",
        "--output",
        metavar="OUT",
        help="where to write; a folder (OUTDIR/) for several inputs or a folder input",
    )
    p.add_argument(
        "--in-place",
        action="store_true",
        help="let OUT be IN (or a folder of inputs): replace the raw take(s), atomically",
    )
    options.add_arguments(p)
    p.add_argument("--format", dest="fmt", help="output format (livelink, csv, json, npz, gltf)")
    p.add_argument(
        "--compress",
        action="store_true",
        help="npz output: deflate it (slower; a take's float64 values hardly shrink)",
    )
    p.add_argument(
        "--scale",
        type=float,
        metavar="FACTOR",
        help="multiply the blendshape values by FACTOR first (0.01: a take in percent); "
        "without it a take far outside [0, 1] is refused",
    )
    p.add_argument(
        "--jobs", type=int, default=1, metavar="N", help="batch: clean N files at once (processes)"
    )
    p.add_argument(
        "--cluster",
        metavar="ADDRESS",
        help="batch: one task per file on a running Dask scheduler (tcp://host:8786, or its "
        "--scheduler-file JSON); a rerun skips the files done (docs/SCALE.md)",
    )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from faceclean.cli import clean_batch
    from faceclean.cli.clean_take import clean_one
    from faceclean.errors import FacecleanError

    if args.output is None:
        if not args.in_place:
            raise FacecleanError("give -o OUT (or --in-place to replace the input)")
        if len(args.input) > 1 or Path(args.input[0]).is_dir():
            raise FacecleanError("--in-place without -o is for one file: give -o OUTDIR/")
        args.output = args.input[0]
    if clean_batch.is_batch(args.input, args.output):
        return clean_batch.run(args)
    if args.jobs != 1 or args.cluster is not None:
        flag = "--jobs" if args.jobs != 1 else "--cluster"
        raise FacecleanError(f"{flag} is for a batch (several files, or a folder)")
    print(clean_one(args, args.input[0], args.output))
    return 0
