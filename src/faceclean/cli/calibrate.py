"""``faceclean calibrate TAKE -o calib.json``: measure a per-channel level mapping.

Record a short take: hold a neutral face for the first second (blinking is fine), then,
optionally, move through each expression as far as it goes (range of motion). The file
maps every channel's neutral to 0 (gain, offset, curve 1, clamp [0, 1]) and keeps its
range, lifting a channel's observed top to 1 only with evidence: ``--rom`` (the take is a
range of motion: every moved channel is lifted) or ``--tracker mediapipe`` (the channels
that tracker under-reads: eyeWide, cheekSquint, noseSneer). Eyelids stay blink-aware.
Gains are capped (calibration.MAX_GAIN) and every gain above 2 is printed. Use the file
with ``clean --calibration``, ``relay --calibration`` and ``info --calibration``; the
equations are in faceclean.calibration.

Guided (faceclean.guided): ``--print-script`` shows the script (about 34 s of prompts);
``--guided TAKE`` finds each prompt in a take of it (robust to a late, slow, uneven
person) and fits a per-face adaptation of the shipped cleaner: for ``--tracker mediapipe``
the face's reading at rest of the mouth and gaze (the map's mouth, cheeks and gaze rise
from it) and a linear correction after the shipped map, cross-channel within a channel
group, pivoted on the opening neutral and shrunk toward the map alone; for ``arkit``
per-channel levels. ``--guided --live URL`` prompts in the terminal and records the stream
(cli/calibrate_live.py). Any prompt not seen stops it, nothing written, unless
``--partial``.
"""

from __future__ import annotations

import argparse

from faceclean.calibration import NEUTRAL_S
from faceclean.cli import options

HELP = "measure a per-channel level mapping (neutral, range) from a short take"
EPILOG = """\
record a take: hold a neutral face for the first second (blinking is fine), then,
optionally, move through each expression as far as it goes. Then:
  faceclean calibrate neutral.csv -o calib.json         neutral only: ranges are kept
  faceclean calibrate rom.csv -o calib.json --rom       a range of motion: tops map to 1
  faceclean calibrate take.csv -o calib.json --tracker mediapipe   lift MediaPipe's weak ones
  faceclean clean take.csv -o out.csv --calibration calib.json
  faceclean info take.csv --calibration calib.json    (its effect; 'info calib.json': the file)
  faceclean relay ... --calibration calib.json
guided (a script of prompts; its take adapts the cleaner to one face):
  faceclean calibrate --print-script                 the prompts, their times and aims
  faceclean calibrate --guided guided.csv -o calib.json --tracker mediapipe
  faceclean calibrate --guided --live vmc://:39540 -o calib.json --tracker mediapipe
with --tracker mediapipe (no --rom) the file holds the face's rest reading of the mouth
and the gaze, which the shipped MediaPipe map measures the mouth's, cheeks' and gaze's
rises from, and no levels (the map was fitted on MediaPipe's raw scores); otherwise
neutral maps to 0; with --rom each channel's observed top (99.5th percentile) maps to 1,
the gain capped; eyelids stay blink-aware (blinks still
close fully); every channel whose gain exceeds 2 is printed.
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "take",
        metavar="TAKE",
        nargs="?",
        help="a neutral hold, then optionally a range of motion (with --guided: the script)",
    )
    p.add_argument("-o", "--output", metavar="FILE", help="calibration .json")
    p.add_argument(
        "--print-script",
        nargs="?",
        const="text",
        choices=("text", "json"),
        help="print the guided script (json: as a file --script reads, to start your own from)",
    )
    p.add_argument(
        "--guided",
        action="store_true",
        help="TAKE is a performance of the guided script (--print-script): fit a per-face "
        "adaptation of the shipped cleaner",
    )
    p.add_argument(
        "--live",
        metavar="URL",
        help="with --guided: prompt here and record the script from a stream (vmc://:PORT, "
        "livelink://:PORT)",
    )
    p.add_argument(
        "--partial",
        action="store_true",
        help="with --guided: write the calibration from the prompts seen even when some were not",
    )
    p.add_argument(
        "--neutral",
        type=float,
        metavar="SECONDS",
        help=f"length of the neutral hold at the start of the take (default {NEUTRAL_S:g})",
    )
    p.add_argument(
        "--scale",
        type=float,
        metavar="FACTOR",
        help="multiply the blendshape values by FACTOR first (0.01: a take in percent), as "
        "clean --scale does: clean with the same --scale; without it a take far outside "
        "[0, 1] is refused",
    )
    p.add_argument(
        "--rom",
        action="store_true",
        help="after the neutral hold the take is a range of motion (every expression as far "
        "as it goes): lift each moved channel's observed top to 1",
    )
    options.add_tracker_argument(p)
    from faceclean.cli import ui

    ui.add_script_argument(p, "with --guided or --print-script")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from faceclean import io
    from faceclean.adjust import Adjust, check_range
    from faceclean.calibration import MAX_GAIN, REPORT_GAIN, calibrate, high_gains
    from faceclean.errors import FacecleanError

    given = [o for o, on in (("-o", args.output), ("--guided", args.guided),
                             ("--partial", args.partial), ("--rom", args.rom),
                             ("--neutral", args.neutral is not None),
                             ("--scale", args.scale is not None)) if on]  # fmt: skip
    if args.print_script and given:  # an option that does nothing here is said, not ignored
        raise FacecleanError(f"--print-script prints the script to the screen: give it without "
                             f"{given[0]}")  # fmt: skip
    plain = [o for o in ("--rom", "--neutral") if args.guided and o in given]
    if plain:
        raise FacecleanError(f"{plain[0]} is the plain calibration's: --guided finds the "
                             "script's own neutral hold and tops")  # fmt: skip
    if args.partial and not args.guided:
        raise FacecleanError("--partial writes a guided calibration from the prompts seen: "
                             "give it with --guided")  # fmt: skip
    if args.print_script:
        from faceclean.guided.script import load

        script = load(args.script)
        print(script.json() if args.print_script == "json" else "\n".join(script.lines()))
        return 0
    if args.script and not args.guided:
        raise FacecleanError("--script is the guided script: give it with --guided")
    if not args.output:
        raise FacecleanError("calibrate: give -o FILE.json (or --print-script)")
    if args.live and not args.guided:
        raise FacecleanError("--live records the guided script: give --guided --live URL")
    if args.guided:
        from faceclean.cli.calibrate_guided import run_guided

        return run_guided(args)
    if not args.take:
        raise FacecleanError("calibrate: give the TAKE")
    out = Path(args.output)
    if out.suffix.lower() != ".json":
        raise FacecleanError(f"-o {out.name}: a calibration is a .json file")
    if out.exists() and Path(args.take).exists() and out.samefile(args.take):
        raise FacecleanError(f"-o {out.name} is the take itself: give another file name")
    io.atomic.check_writable(out)
    anim = io.load(args.take)
    check_range(anim.values, anim.names, Path(args.take).name, args.scale)  # as clean's
    if args.scale is not None:  # the levels of the values as clean --scale gives them
        anim = anim.with_values(Adjust().scaled(args.scale).apply(anim.values, anim.names))
    done = io.paths.verb(out)  # "replaced": said, as the file goes
    neutral = NEUTRAL_S if args.neutral is None else args.neutral
    adjust = calibrate(anim, neutral, take=Path(args.take).name, rom=args.rom, tracker=args.tracker)
    if args.tracker == "mediapipe" and not args.rom:  # the face's rest reading, for the map
        from faceclean.guided.fit import rest_calibration

        facts = {k: adjust.facts[k] for k in ("take", "frames", "neutral_s", "tracker", "rom")}
        adjust = rest_calibration(anim, facts["neutral_s"], facts)
        if adjust.adaptation is None:  # nothing to write: an identity file helps no one
            raise FacecleanError(f"{Path(args.take).name}: no mouth or gaze channel to read "
                                 "at rest (a MediaPipe take has them)")  # fmt: skip
        adjust.save(args.output)
        n = len(adjust.adaptation.rest)
        print(f"{done} {args.output}: the face's rest reading of {n} mouth and gaze channels "
              f"from the first {facts['neutral_s']:.2f} s, for the shipped MediaPipe map; no "
              "levels before it (the map measures rises itself: docs/CALIBRATION.md)")  # fmt: skip
        return 0
    adjust.save(args.output)
    facts = adjust.facts
    print(
        f"{done} {args.output}: {len(facts['channels'])} channels, neutral from the first "
        f"{facts['neutral_s']:.2f} s; {len(facts['moved'])} moved, {len(facts['lifted'])} "
        f"lifted to their top ({'range of motion' if args.rom else f'tracker {args.tracker}'}), "
        f"{len(facts['closed'])} eyelids scaled to close (their blinks)"
    )
    high = high_gains(adjust)
    if high:
        print(f"gain above {REPORT_GAIN:g} on {len(high)} channel{'s' * (len(high) > 1)}:")
    for name, gain, top in high:
        capped = " (capped)" if gain >= MAX_GAIN - 1e-9 else ""
        print(f"  {name:<20} gain {gain:5.2f}{capped}  top {top:.3f}")
    return 0
