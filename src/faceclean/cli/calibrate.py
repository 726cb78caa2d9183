"""``faceclean calibrate TAKE -o calib.json``: measure a per-channel level mapping.

Record a short take: hold a neutral face for the first second (blinking is fine), then,
optionally, move through each expression as far as it goes (range of motion). The file
maps every channel's neutral to 0 and its observed top to 1 (gain, offset, curve 1,
clamp [0, 1]); eyelids stay blink-aware, channels the take never moves keep a safe
near-identity mapping, and weak tracker channels (MediaPipe's eyeWide, cheekSquint,
noseSneer, which never pass a few hundredths) get the gain that lifts them. Use it with
``clean --calibration``, ``relay --calibration`` and ``info --calibration``; the
equations are in faceclean.calibration.
"""

from __future__ import annotations

import argparse

from faceclean.calibration import NEUTRAL_S

HELP = "measure a per-channel level mapping (neutral, range) from a short take"
EPILOG = """\
record a take: hold a neutral face for the first second (blinking is fine), then,
optionally, move through each expression as far as it goes. Then:
  faceclean calibrate rom.csv -o calib.json
  faceclean clean take.csv -o out.csv --calibration calib.json
  faceclean info take.csv --calibration calib.json    (its effect; 'info calib.json': the file)
  faceclean relay ... --calibration calib.json
neutral maps to 0 and each channel's observed top (99.5th percentile) to 1; eyelids stay
blink-aware (blinks still close fully), channels the take never moves keep a near-identity
mapping, weak channels (a few hundredths at most, as MediaPipe's eyeWide) are lifted.
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("take", metavar="TAKE", help="a neutral hold, then optionally a range of motion")
    p.add_argument("-o", "--output", metavar="FILE", required=True, help="calibration .json")
    p.add_argument(
        "--neutral",
        type=float,
        default=NEUTRAL_S,
        metavar="SECONDS",
        help=f"length of the neutral hold at the start of the take (default {NEUTRAL_S:g})",
    )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from faceclean import io
    from faceclean.calibration import calibrate
    from faceclean.errors import FacecleanError

    out = Path(args.output)
    if out.suffix.lower() != ".json":
        raise FacecleanError(f"-o {out.name}: a calibration is a .json file")
    if out.exists() and Path(args.take).exists() and out.samefile(args.take):
        raise FacecleanError(f"-o {out.name} is the take itself: give another file name")
    anim = io.load(args.take)
    adjust = calibrate(anim, args.neutral, take=Path(args.take).name)
    adjust.save(args.output)
    facts = adjust.facts
    print(
        f"wrote {args.output}: {len(facts['channels'])} channels, neutral from the first "
        f"{facts['neutral_s']:.2f} s; {len(facts['moved'])} moved"
        + (f", lifted {', '.join(facts['lifted'])}" if facts["lifted"] else "")
    )
    return 0
