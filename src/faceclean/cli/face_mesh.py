"""``faceclean face-mesh -o face.glb``: export faceclean's stylised face as GLB, with its
52 morph targets named by ARKit channel (mesh.extras.targetNames)."""

from __future__ import annotations

import argparse

HELP = "export the stylised face with 52 ARKit morph targets as GLB"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", metavar="GLB", required=True, help="output file (.glb)")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from faceclean.errors import FacecleanError
    from faceclean.face import mesh
    from faceclean.io import gltf_take
    from faceclean.io.paths import verb

    if Path(args.output).suffix.lower() != ".glb":
        raise FacecleanError(f"{args.output}: the face mesh is written as .glb")
    face = mesh.stylised()
    done = verb(args.output)
    gltf_take.save_mesh(face, args.output)
    print(
        f"{done} {args.output}: {len(face.vertices)} vertices, {len(face.faces)} triangles, "
        f"{int(face.present.sum())} ARKit morph targets"
    )
    return 0
