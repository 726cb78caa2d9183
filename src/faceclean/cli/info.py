"""``faceclean info FILE``: what a capture holds: channels, rate, gaps, value ranges.

``info TAKE --calibration calib.json`` adds what the level mapping does to the take (its
rules, and the value range after it); ``info calib.json`` describes a calibration file.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

HELP = "describe an animation file (channels, rate, gaps, ranges), a calibration or a model file"
GAP_FACTOR = 1.5  # a step longer than this many median steps has dropped frames
SHOWN = 8  # level rules listed before "... and N more"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE", help="animation file")
    p.add_argument("--json", action="store_true", help="print the facts as JSON")
    p.add_argument(
        "--calibration",
        metavar="FILE",
        help="also show the effect of this level mapping (from 'faceclean calibrate')",
    )


def describe(anim) -> dict[str, Any]:
    """Facts about an Animation (JSON-ready): counts, rate in Hz, seconds, gaps, ranges."""
    from faceclean.animation import MIN_DT
    from faceclean.channels import ARKIT52, canonical

    valid = anim.valid
    dt = np.diff(anim.times)  # s, over every row (tracking loss rows keep their times)
    positive = dt[dt > MIN_DT]  # a smaller step is a duplicate
    median = float(np.median(positive)) if len(positive) else 0.0
    gap_at = np.flatnonzero(dt > GAP_FACTOR * median) if median else np.zeros(0, int)
    dropped = int(sum(round(dt[i] / median) - 1 for i in gap_at))
    arkit = {canonical(n) for n in anim.names} - {None}
    rows = anim.values[valid]
    infinite = int(np.isinf(rows).sum())  # cells counted apart: the range is of the finite
    rows = np.where(np.isinf(rows), np.nan, rows)
    with np.errstate(all="ignore"):
        lo = np.nanmin(rows, axis=0) if len(rows) else np.full(anim.n_channels, np.nan)
        hi = np.nanmax(rows, axis=0) if len(rows) else np.full(anim.n_channels, np.nan)
    outside = [
        {"channel": n, "min": float(a), "max": float(b)}
        for n, a, b in zip(anim.names, lo, hi, strict=True)
        if a < 0.0 or b > 1.0
    ]
    return {
        "format": anim.meta.get("format"),
        "channels": anim.n_channels,
        "arkit_channels": len(arkit),
        "not_arkit": [n for n in anim.names if canonical(n) is None],
        "arkit_absent": [n for n in ARKIT52 if n not in arkit],
        "frames": anim.n_frames,
        "missing_frames": int((~valid).sum()),
        "rate_hz": 1.0 / median if median else 0.0,
        "duration_s": anim.duration,
        "gaps": [{"at_s": float(anim.times[i]), "length_s": float(dt[i])} for i in gap_at],
        "dropped_frames": dropped,
        "non_increasing_steps": int((dt <= 0).sum()),
        "min": float(np.nanmin(lo)) if np.isfinite(lo).any() else None,
        "max": float(np.nanmax(hi)) if np.isfinite(hi).any() else None,
        "outside_0_1": outside,
        "infinite_cells": infinite,
        "pose_channels": list(anim.meta.get("pose_names", ())),
        "timecode_start": anim.meta.get("timecode_start"),
        # a relay recording of a stream without timecode keeps its arrival times
        "timecode_source": "arrival"
        if "ArrivalTime" in anim.meta.get("pose_names", ())
        else ("file" if anim.meta.get("timecode_start") is not None else None),
    }


def run(args: argparse.Namespace) -> int:
    from faceclean import io, strict_json
    from faceclean.adjust import Adjust, is_level_file

    if is_level_file(args.file):
        return _levels_file(args)
    from faceclean.learned.formats import is_model_file

    if is_model_file(args.file):
        return _model_file(args)
    from faceclean.filters import compiled

    anim = io.load(args.file)
    facts = describe(anim)
    adjust = Adjust.load(args.calibration) if args.calibration else None
    if adjust is not None:
        after = describe(anim.with_values(adjust.apply(anim.values, anim.names)))
        facts["levels"] = {
            "file": args.calibration,
            "rules": adjust.describe(anim.names),
            "after": {k: after[k] for k in ("min", "max", "outside_0_1")},
        }
    if args.json:
        print(strict_json.dumps(facts, indent=2))  # non-finite numbers: null, never Infinity
        return 0
    lines = [
        ("file", args.file),
        ("format", facts["format"]),
        ("channels", _channels(facts)),
        ("frames", f"{facts['frames']} ({facts['missing_frames']} missing: tracking loss)"),
        ("rate", f"{facts['rate_hz']:.3f} Hz (median step)"),
        ("duration", f"{facts['duration_s']:.3f} s"),
        ("gaps", _gaps(facts)),
        ("range", _range(facts)),
        ("cleaning", compiled.status(facts["frames"])),
    ]
    if facts["pose_channels"]:
        lines += _pose_lines(facts["pose_channels"])
    if facts["timecode_start"] is not None:
        from faceclean.io.livelink_csv import timecode_text

        how = {
            "arrival": "the arrival time: the source sent no timecode (ArrivalTime column)",
            "file": "as the file carries it",
        }[facts["timecode_source"]]
        lines.append(("timecode", f"starts {timecode_text(facts['timecode_start'])}, {how}"))
    if adjust is not None:
        rules = list(facts["levels"]["rules"])
        about = rules.pop() if adjust.facts else None  # describe()'s facts line comes last
        touched = len(adjust.levels(anim.names).active)
        lines.append(
            ("calibration", f"{args.calibration}: levels on {touched} of {anim.n_channels} "
             f"channels ({len(rules)} patterns)")
        )  # fmt: skip
        lines += [("", r) for r in rules[:SHOWN]]
        if len(rules) > SHOWN:  # SHOWN + this = every pattern line
            lines.append(("", f"... and {len(rules) - SHOWN} more"))
        if about:
            lines.append(("", about))
        lines.append(("after", "range " + _range(after)))
    for key, text in lines:
        print(f"{key:<12}{plain(text)}")
    return 0


def plain(text: str) -> str:
    """``text`` as a terminal should show it: a character that is not printable (an escape
    code in a channel's name) written as its escape, never acted on."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)


def _pose_lines(names: list[str]) -> list[tuple[str, str]]:
    """The pose columns: head/eye angles (cleaned by the rotation filter) and any other
    column (passed through)."""
    from faceclean.channels import pose_name

    angles = [n for n in names if pose_name(n) is not None]
    other = [n for n in names if pose_name(n) is None]
    lines = []
    if angles:
        text = f"{len(angles)} head/eye angles (rad): {', '.join(angles)}"
        lines.append(("pose", text + "; cleaned by the rotation filter (head, eyes)"))
    if other:
        lines.append(("passthrough", ", ".join(other)))
    return lines


def _levels_file(args: argparse.Namespace) -> int:
    """``info calib.json``: the rules, then the measured neutral and top per channel."""
    from faceclean import strict_json
    from faceclean.adjust import Adjust

    adjust = Adjust.load(args.file)
    if args.json:
        print(strict_json.dumps(adjust.to_dict(), indent=2))
        return 0
    print(f"{'file':<12}{args.file}")
    print(f"{'format':<12}faceclean-adjust/1 (level mapping)")
    for line in adjust.describe():
        print(f"{'':<12}{plain(line)}")
    chans = adjust.facts.get("channels", {})
    if chans and isinstance(chans, dict):  # the facts are what was measured, as written
        print(f"{'':<12}{'channel':<20}{'neutral':>9}{'top':>9}{'noise':>9}")
        for name, c in chans.items():
            c = c if isinstance(c, dict) else {}
            cols = "".join(_measured(c.get(k)) for k in ("neutral", "top", "noise"))
            print(f"{'':<12}{plain(str(name)):<20}{cols}")
    return 0


def _measured(v: object) -> str:
    """One measured fact, 9 wide: a number, or "-" where none was measured (null: a
    guided calibration's top of a channel no prompt aims at)."""
    number = isinstance(v, (int, float)) and not isinstance(v, bool)
    return f"{v:>9.4f}" if number else f"{'-':>9}"


def _model_file(args: argparse.Namespace) -> int:
    """``info model.npz``: what a checkpoint is (its format, the method that runs it, its
    channels) and the facts its trainer stored (what it was trained and validated on)."""
    from faceclean import strict_json
    from faceclean.learned.formats import METHODS, read

    config, arrays = read(args.file)
    fmt = config.get("format")
    if args.json:
        print(strict_json.dumps({"file": str(args.file), "config": config}, indent=2))
        return 0
    method = METHODS.get(fmt)
    print(f"{'file':<12}{args.file}")
    print(f"{'format':<12}{fmt} (a model: --method {method} --model FILE)" if method
          else f"{'format':<12}{fmt!r}: not a model faceclean runs")  # fmt: skip
    names = config.get("outputs") or config.get("channels") or config.get("names")
    if isinstance(names, list):
        print(f"{'channels':<12}{len(names)}")
    parameters = sum(int(getattr(a, "size", 0)) for a in arrays.values())
    print(f"{'parameters':<12}{parameters}")
    skip = {"format", "inputs", "outputs", "channels", "names"}
    for key, value in config.items():
        if key not in skip and isinstance(value, str | int | float | bool | list):
            text = value
            if isinstance(value, list):  # at most 8 shown, the rest counted
                more = f" and {len(value) - 8} more" if len(value) > 8 else ""
                text = ", ".join(map(str, value[:8])) + more
            print(f"{'':<12}{key}: {text}")
    return 0


def _channels(f: dict[str, Any]) -> str:
    text = f"{f['channels']} ({f['arkit_channels']} ARKit)"
    if f["not_arkit"]:
        text += "; not ARKit: " + ", ".join(f["not_arkit"])
    absent = f["arkit_absent"]
    if absent and f["arkit_channels"]:
        shown = ", ".join(absent[:8]) + (f" and {len(absent) - 8} more" if len(absent) > 8 else "")
        text += f"; {len(absent)} ARKit absent: {shown}"
    return text


def _gaps(f: dict[str, Any]) -> str:
    if not f["gaps"]:
        text = "none (no step longer than 1.5 x the median)"
    else:
        longest = max(g["length_s"] for g in f["gaps"])
        shown = ", ".join(f"{g['at_s']:.2f} s" for g in f["gaps"][:5])
        more = f" and {len(f['gaps']) - 5} more" if len(f["gaps"]) > 5 else ""
        text = (
            f"{len(f['gaps'])} ({f['dropped_frames']} dropped frames, longest "
            f"{longest * 1000:.0f} ms) at {shown}{more}"
        )
    if f["non_increasing_steps"]:
        text += f"; {f['non_increasing_steps']} repeated or backwards timestamps"
    return text


def _range(f: dict[str, Any]) -> str:
    inf = f.get("infinite_cells", 0)
    said = f"; {inf} cells infinite (read as missing)" if inf else ""
    if f["min"] is None:
        return "no values" + said
    text = f"min {_num(f['min'], 4)}, max {_num(f['max'], 4)}"
    out = f["outside_0_1"]
    if out:
        worst = ", ".join(f"{o['channel']} [{_num(o['min'], 3)}, {_num(o['max'], 3)}]"
                          for o in out[:6])  # fmt: skip
        more = f" and {len(out) - 6} more" if len(out) > 6 else ""
        text += f"; {len(out)} channels outside [0, 1]: {worst}{more}"
    else:
        text += "; all within [0, 1]"
    return text + said


def _num(v: float, places: int) -> str:
    """A value to ``places`` decimals; one far past any weight in 4 significant digits."""
    return f"{v:.{places}f}" if abs(v) < 1e4 else f"{v:.4g}"
