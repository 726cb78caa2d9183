"""``faceclean plot NOISY -o FIG.png``: chosen channels over time, in the manner of the
paper's figures: input, truth, the cleaned curve and compared methods."""

from __future__ import annotations

import argparse

from faceclean.cli import options

MAX_PANELS = 61  # channels in one figure: a take's 52 blendshapes and 9 head/eye angles
HELP = "plot channels over time: input, truth, cleaned and compared methods (PNG, SVG, PDF)"
EPILOG = options.SETTINGS_HELP  # the cleaner options and --set syntax


def add_method_arguments(p: argparse.ArgumentParser, verb: str = "plot") -> None:
    """NOISY, --truth, the cleaner options, --compare: shared by ``plot`` and ``report``."""
    p.add_argument("input", metavar="NOISY", help=f"animation file to clean and {verb}")
    p.add_argument("--truth", metavar="CLEAN", help="the clean animation (any timestamps)")
    options.add_arguments(p, "the cleaner shown as 'cleaned'", levels="every cleaner")
    p.add_argument(
        "--compare",
        metavar="METHOD",
        nargs="+",
        action="extend",
        default=[],
        help="other cleaners to show beside it, settings inline: 'one-euro:min_cutoff=2,beta=0.1'",
    )


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_method_arguments(p)
    p.add_argument(
        "--channels",
        metavar="A,B",
        help="channels, comma-separated (default: the 4 the cleaner changed most)",
    )
    p.add_argument("-o", "--output", metavar="FIG", required=True, help="figure .png/.svg/.pdf")
    p.add_argument("--start", type=float, help="window start, s from the first frame")
    p.add_argument("--end", type=float, help="window end, s from the first frame")


def comparison_from(args: argparse.Namespace):
    """Load NOISY (and --truth) and clean with the cleaner options, then --compare."""
    from faceclean import io
    from faceclean.evaluation import comparison
    from faceclean.resolve import DEFAULT

    noisy = io.load(args.input)
    truth = io.load(args.truth) if args.truth else None
    label = " ".join([options.words(args) or DEFAULT, *args.params])
    methods = [(label, options.choice(args)), *args.compare]
    return comparison.compare(noisy, truth, methods, options.calibration(args))


def run(args: argparse.Namespace) -> int:
    from faceclean.errors import FacecleanError
    from faceclean.io.atomic import check_writable
    from faceclean.io.paths import verb
    from faceclean.report import plot

    check_writable(args.output)  # now, not after cleaning
    asked = [c.strip() for c in (args.channels or "").split(",") if c.strip()]
    channels = list(dict.fromkeys(asked)) or None  # each once, in the order given
    if channels and len(channels) > MAX_PANELS:
        raise FacecleanError(f"--channels names {len(channels)} channels: a figure shows at "
                             f"most {MAX_PANELS} (a take has 52 blendshapes)")  # fmt: skip
    comp = comparison_from(args)
    done = verb(args.output)
    plot.save_figure(comp, args.output, channels, args.start, args.end)
    shown = ", ".join(comp.outputs)
    print(f"{done} {args.output}: {comp.input.n_frames} frames, cleaned with {shown}")
    return 0
