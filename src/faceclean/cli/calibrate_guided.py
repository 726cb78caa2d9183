"""``faceclean calibrate --guided TAKE -o calib.json [--tracker mediapipe|arkit]``.

The take is a performance of the guided script (``calibrate --print-script``). Printed:
one line per prompt (where it was found in the take, seen or why not, its channels' peak
before and after the calibration against the script's aim), then what the file changes.
A prompt not seen, or a take that did not follow the script, stops the command (exit 2)
and nothing is written, unless ``--partial``. ``--live URL`` records the take from a
stream first (cli/calibrate_live.py).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from faceclean.channels import GROUPS

TOP_CHANGES = 6  # the adaptation's largest changes printed


def run_guided(args: argparse.Namespace) -> int:
    from faceclean import io
    from faceclean.adjust import Adjust, check_range
    from faceclean.errors import FacecleanError
    from faceclean.guided.fit import guided
    from faceclean.guided.script import load

    script = load(args.script)  # None: the shipped one
    out = Path(args.output)
    if out.suffix.lower() != ".json":
        raise FacecleanError(f"-o {out.name}: a calibration is a .json file")
    if args.live:
        if args.take:
            raise FacecleanError("--live records the take: give no TAKE with it")
        from faceclean.cli.calibrate_live import record

        io.atomic.check_writable(out)
        anim, label = record(args.live, script), f"live {args.live}"
    else:
        if not args.take:
            raise FacecleanError("--guided needs the TAKE (or --live URL)")
        if out.exists() and Path(args.take).exists() and out.samefile(args.take):
            raise FacecleanError(f"-o {out.name} is the take itself: give another file name")
        io.atomic.check_writable(out)
        anim, label = io.load(args.take), Path(args.take).name
    check_range(anim.values, anim.names, label, args.scale)  # as clean's and the plain one's
    if args.scale is not None:  # fitted on the values clean --scale then hands the cleaner
        anim = anim.with_values(Adjust().scaled(args.scale).apply(anim.values, anim.names))
    result = guided(anim, args.tracker, script, take=label)
    for line in report(result):
        print(line)
    why = result.alignment.shortfall()
    fits = result.alignment.fitted_from
    if why is not None and not args.partial:
        raise FacecleanError(f"{why}; nothing written (--partial writes from {fits})")
    if why is not None:
        print(f"warning: {why}; written from {fits} (--partial)")
    done = io.paths.verb(out)
    result.adjust.save(out)
    print(f"{done} {out} (tracker {result.tracker}; use it with --calibration {out.name}"
          f"{' --tracker ' + result.tracker if result.tracker != 'arkit' else ''})")  # fmt: skip
    return 0


def report(result) -> list[str]:
    """The lines ``calibrate --guided`` prints (a Guided from faceclean.guided.fit)."""
    lines = [f"{'prompt':<12} {'take s':>13}  {'':<14} peak before -> after (aim)"]
    for g in result.alignment.segments:
        pid = g.prompt.id
        where = f"{g.t0:6.2f}-{g.t1:6.2f}"
        peak = ""
        if pid in result.before:
            peak = f"{result.before[pid]:.2f} -> {result.after[pid]:.2f} ({result.target[pid]:.2f})"
        lines.append(f"{pid:<12} {where:>13}  {g.why:<14} {peak}")
    adjust = result.adjust
    if adjust.adaptation is not None:
        ad = adjust.adaptation
        cross = sum(1 for o, row in ad.matrix.items() for i in row if i != o)
        lines.append(
            f"adaptation after the shipped cleaner ({ad.facts.get('cleaner', '?')}): "
            f"{len(ad.channels)} channels corrected, {len(ad.offset)} offsets, "
            f"{cross} cross-channel terms"
        )
        big = sorted(
            ((abs(v), o, i, v) for o, row in ad.matrix.items() for i, v in row.items()),
            reverse=True,
        )[:TOP_CHANGES]
        for _, o, i, v in big:
            what = "gain" if o == i else f"+ {i} x"
            lines.append(f"  {o:<20} {what} {1 + v if o == i else v:+.3f}")
        if ad.rest:
            n, m = len(ad.rest), len(ad.rest_outputs)
            lines.append(f"rest reading of {n} mouth and gaze channels (this face's "
                         f"neutral): {m} mouth, cheek and gaze channels rise from it")  # fmt: skip
        for group, (e_map, e_own) in ad_own(adjust).items():
            lines.append(f"{group} read as their own rise alone: mean square error over "
                         f"this face's prompts {e_own:.3f}, the map's {e_map:.3f}")  # fmt: skip
        for name, (knee, top) in ad.closure.items():
            lines.append(f"  {name:<20} reads {top:.2f} shut: lifted from {knee:.2f} so that "
                         "this face's closure reads 1")  # fmt: skip
    else:
        chans = adjust.facts.get("channels", {})
        lifted = adjust.facts.get("lifted", [])
        lines.append(f"levels on {len(chans)} channels; {len(lifted)} scaled to their prompts' aim")
        for name in lifted[: TOP_CHANGES * 2]:
            c = chans[name]
            lines.append(f"  {name:<20} neutral {c['neutral']:.3f} gain {c['gain']:.2f}")
    return lines


def ad_own(adjust) -> dict[str, list[float]]:
    """{group: [the map's error, its own rise's]} of the groups read as their own rise."""
    own = set(adjust.adaptation.own)
    found = adjust.facts.get("guided", {}).get("own", {})
    return {g: e for g, e in found.items() if own & set(GROUPS.get(g, ()))}
