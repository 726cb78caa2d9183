"""``faceclean report NOISY -o report.html``: one self-contained HTML file with the
measures, curves per channel group and the input and cleaned animation on a 3D face."""

from __future__ import annotations

import argparse

from faceclean.cli import options
from faceclean.cli.plot import add_method_arguments

HELP = "write a self-contained HTML report: measures, curves and a 3D face, input vs cleaned"
EPILOG = options.SETTINGS_HELP  # the cleaner options and --set syntax


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_method_arguments(p, "show")
    p.add_argument(
        "--mesh",
        metavar="FILE",
        help="face mesh with ARKit morph targets (.glb or .npz; default: faceclean's own face)",
    )
    p.add_argument("-o", "--output", metavar="HTML", required=True, help="report file (.html)")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from faceclean import report
    from faceclean.cli.plot import comparison_from
    from faceclean.errors import FacecleanError
    from faceclean.face import mesh
    from faceclean.io.atomic import check_writable
    from faceclean.io.paths import verb

    if Path(args.output).suffix.lower() not in (".html", ".htm"):
        raise FacecleanError(f"{args.output}: the report must be an .html file")
    check_writable(args.output)  # now, not after cleaning and building the page
    face = mesh.load(args.mesh) if args.mesh else None
    comp = comparison_from(args)
    done = verb(args.output)
    size = report.write(comp, args.output, face, source=Path(args.input).name)
    print(
        f"{done} {args.output} ({size / 1e6:.1f} MB): {comp.input.n_frames} frames, "
        f"cleaned with {', '.join(comp.outputs)}"
    )
    return 0
