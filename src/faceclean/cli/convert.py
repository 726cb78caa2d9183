"""``faceclean convert IN -o OUT``: change an animation's file format, values untouched.

To .glb/.gltf: a glTF source gets its weights written back into a copy of itself; any
other take becomes a new file, a face mesh (``--mesh``, else the stylised face) with 52
ARKit morph targets and the take as its morph-weight animation.
"""

from __future__ import annotations

import argparse

HELP = "convert between Live Link CSV, CSV, JSON, NPZ and glTF/GLB (any take to an animated GLB)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="IN", help="animation file to read")
    p.add_argument("-o", "--output", metavar="OUT", required=True, help="where to write")
    p.add_argument("--format", dest="fmt", help="output format (livelink, csv, json, npz, gltf)")
    p.add_argument(
        "--mesh",
        metavar="FILE",
        help="for .glb/.gltf output: the face to animate (npz, or GLB/glTF with ARKit-named "
        "morph targets); default the stylised face (faceclean face-mesh)",
    )
    p.add_argument(
        "--in-place",
        action="store_true",
        help="allow OUT to be IN (replaced atomically, once complete); without it, a take "
        "is never converted over itself",
    )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from faceclean import io
    from faceclean.errors import FacecleanError
    from faceclean.timing import refuse_restarts

    rule = "a take is never converted over itself"
    io.paths.onto_input(args.input, args.output, args.in_place, rule)
    done = io.paths.verb(args.output)
    anim = io.load(args.input)
    refuse_restarts(anim, Path(args.input).name)  # as clean refuses them
    fmt = io.output_format(args.output, anim.meta.get("format"), args.fmt)
    new_gltf = fmt == "gltf" and (args.mesh is not None or "gltf" not in anim.meta)
    if args.mesh is not None and fmt != "gltf":
        raise FacecleanError("--mesh is for glTF output (.glb or .gltf)")
    if not new_gltf:
        io.save(anim, args.output, fmt=args.fmt)
        print(
            f"{done} {args.output}: {anim.n_frames} frames, {anim.n_channels} channels "
            f"({anim.meta.get('format')} -> {fmt})"
        )
        return 0

    from faceclean.face import mesh as face_mesh
    from faceclean.io import gltf_take
    from faceclean.io.atomic import atomic_open

    suffix = Path(args.output).suffix.lower()
    mesh = face_mesh.load(args.mesh) if args.mesh is not None else face_mesh.stylised()
    with atomic_open(args.output, "wb") as f:
        counts = gltf_take.write(anim, f, args.output, mesh, name=Path(args.input).stem)
    kept = anim.n_frames - counts["lost"] - counts["unordered"]
    dropped = [f"{counts['lost']} tracking-loss"] if counts["lost"] else []
    dropped += [f"{counts['unordered']} non-advancing"] if counts["unordered"] else []
    rate = (
        f" at {counts['fps']:g} fps (frames 0-{counts['frame_end']}: set this rate in a "
        "frame-based importer such as Blender before importing, docs/FORMATS.md)"
        if "fps" in counts
        else ""
    )
    print(
        f"{done} {args.output}: {kept} keyframes over {counts['seconds']:.2f} s{rate}, "
        f"{counts['channels']} ARKit channels, on {mesh.name} ({len(mesh.vertices)} vertices, "
        f"52 morph targets)"
        + (f"; dropped {' and '.join(dropped)} frames" if dropped else "")
        + f" ({anim.meta.get('format')} -> {'gltf' if suffix == '.gltf' else 'glb'})"
    )
    return 0
