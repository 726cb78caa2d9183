"""The cleaner options every cleaning command shares (``clean``, ``relay``, ``plot``,
``report``): ``--method``/``--model``/``--preset`` and ``--set``, read by
``faceclean.resolve``, and ``--calibration`` (the level mapping before the cleaner).
Not a command itself."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from faceclean.resolve import Choice

SETTINGS_HELP = """\
choosing the cleaner (one of --method, --model, --preset; default: the shipped model):
  --method one-euro                 a method: its shipped tuned preset, or its defaults
  --method lstm | fc | gbt          a shipped learned model
  --model my.npz | my.onnx          a learned model file (also --method my.npz)
  --preset tuned.json | one-euro    a preset file from 'faceclean tune', or a shipped one
                                    (a rotation preset, 'tune --method rotation', is the
                                    head and eye angles' and goes with --method/--model)
  --tracker mediapipe               the cleaner shipped for MediaPipe's output (levels too)
settings (--set, repeatable; values: true/false, numbers, JSON lists, else text):
  --set min_cutoff=2                one setting for every channel; the rest of a tuned
                                    preset is kept
  --set jawOpen.min_cutoff=2.0      per channel: a channel name, a glob or a group
  --set 'eyeBlink*.beta=0.1'        (eyes, brows, jaw, mouth, cheeks_nose); the smoothing
                                    settings of ema, one-euro, kalman, gaussian
  --set 'eyeBlink*.gain=1.2'        levels before the cleaner: gain, offset, curve,
  --set tongueOut.off               clamp=LO,HI, off (faceclean.adjust)
  an unknown key is refused with the list of valid ones
"""


def add_arguments(
    p: argparse.ArgumentParser, what: str = "the cleaner", levels: str = "the cleaner"
) -> None:
    p.add_argument(
        "--method",
        metavar="NAME",
        help=f"{what}: a method, a shipped model or preset, or a model file "
        "(default: the shipped model)",
    )
    p.add_argument("--model", metavar="FILE", help="learned model file (.npz or .onnx)")
    add_tracker_argument(p)
    p.add_argument("--preset", metavar="FILE", help="preset file or shipped preset's name")
    p.add_argument(
        "--set",
        dest="params",
        metavar="[CHANNEL.]KEY=VALUE",
        action="append",
        default=[],
        help="setting, repeatable; per channel by name, glob or group (see below)",
    )
    p.add_argument(
        "--calibration",
        metavar="FILE",
        help=f"level mapping from 'faceclean calibrate', applied before {levels}",
    )


def add_tracker_argument(p: argparse.ArgumentParser) -> None:
    """``--tracker NAME``: which tracker made the take (``channels.TRACKERS``, the one list
    of tracker profiles; default ``arkit``). Any command that needs it adds it here."""
    from faceclean.channels import DEFAULT_TRACKER, TRACKERS

    p.add_argument(
        "--tracker",
        choices=tuple(TRACKERS),
        default=DEFAULT_TRACKER,
        help=f"the tracker that made the take (default {DEFAULT_TRACKER}); its profile "
        "names the channels it under-reads (mediapipe: eyeWide, cheekSquint, noseSneer), and "
        "without --method/--model/--preset it picks the cleaner shipped for it (mediapipe: "
        "a learned map onto ARKit's levels)",
    )


def calibration(args: argparse.Namespace):
    """The ``--calibration`` level mapping (faceclean.adjust.Adjust), None without one."""
    from faceclean.adjust import Adjust

    path = getattr(args, "calibration", None)
    if not path:
        return None
    from faceclean.adaptation import check_cleaner, check_tracker

    adjust = Adjust.load(path)
    check_tracker(adjust, getattr(args, "tracker", None), f"--calibration {path}")
    check_cleaner(adjust.adaptation, words(args), f"--calibration {path}")  # its cleaner's own
    return adjust


def pose_preset(args: argparse.Namespace) -> str | None:
    """--preset when it names a rotation preset (head and eye angles, ``tune --method
    rotation``): it goes with the blendshapes' own --method/--model, not instead of them."""
    from faceclean.filters import presets

    preset = getattr(args, "preset", None)
    if not preset or not (str(preset).lower().endswith(".json") or preset == "rotation"):
        return None
    return preset if presets.read(preset)["method"] == "rotation" else None


def words(args: argparse.Namespace) -> str | None:
    """What --method/--model/--preset name (None: the shipped default); a rotation
    --preset names the angles' cleaner (``pose_preset``), not this one."""
    from faceclean.errors import FacecleanError

    given = [o for o in ("method", "model", "preset") if getattr(args, o, None)]
    if "preset" in given and pose_preset(args) is not None:
        given.remove("preset")
    if len(given) > 1:
        if "model" in given:
            raise FacecleanError("--model is the cleaner: give it without --method/--preset")
        raise FacecleanError(f"give one of --method, --model, --preset (got {', '.join(given)})")
    model = getattr(args, "model", None)
    if model and not str(model).lower().endswith((".npz", ".onnx")):
        raise FacecleanError(f"{model}: a model is a .npz or an .onnx file")
    if given:
        return getattr(args, given[0])
    from faceclean.resolve import tracker_words

    return tracker_words(getattr(args, "tracker", None))


def choice(args: argparse.Namespace) -> Choice:
    """The cleaner the options name, settings applied (faceclean.resolve)."""
    from faceclean.resolve import resolve

    return resolve(words(args), args.params, pose_preset=pose_preset(args))
