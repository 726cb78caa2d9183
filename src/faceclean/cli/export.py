"""``faceclean export MODEL -o model.onnx``: the learned cleaner as a one-step ONNX graph.

Every piece of recurrent state is an explicit input and output (see
faceclean.learned.export), so the engine that runs it owns the state. Needs the ``onnx``
package, not torch.
"""

from __future__ import annotations

import argparse

HELP = "export a learned model (.npz) as a single-step ONNX graph with explicit state"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", metavar="MODEL", help="model checkpoint (.npz)")
    p.add_argument("-o", "--output", metavar="OUT", required=True, help="ONNX file to write")
    p.add_argument(
        "--check", action="store_true", help="run one step in ONNX Runtime against numpy"
    )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from faceclean.errors import FacecleanError
    from faceclean.io.atomic import check_writable
    from faceclean.io.paths import verb
    from faceclean.learned.export import export

    if Path(args.model).resolve() == Path(args.output).resolve():
        raise FacecleanError("OUT must not be the model file")
    if Path(args.output).suffix.lower() != ".onnx":  # every reader of ONNX looks for it
        raise FacecleanError(f"-o {Path(args.output).name}: an ONNX graph is a .onnx file")
    check_writable(args.output)
    done = verb(args.output)
    facts = export(args.model, args.output)
    print(
        f"{done} {args.output}: {facts['channels']} channels, {facts['layers']} x "
        f"{facts['hidden']} LSTM, {facts['bytes'] / 1e6:.2f} MB"
    )
    if args.check:
        err = _check(args.model, args.output)
        print(f"check: ONNX Runtime vs numpy over 200 steps, max |diff| = {err:.2g}")
        if not err <= 1e-5:
            raise FacecleanError(f"ONNX output differs from numpy by {err:.2g}")
    return 0


def _check(model: str, onnx_path: str) -> float:
    """Max |ONNX - numpy| over 200 steps of a seeded random walk, 2 streams."""
    import numpy as np

    from faceclean.learned.lstm import Learned
    from faceclean.learned.onnx import OnnxLearned

    a, b = Learned(model), OnnxLearned(onnx_path)
    m = len(a.names)
    rng = np.random.default_rng(0)
    x = np.clip(0.3 + np.cumsum(rng.normal(0, 0.02, (200, 2, m)), axis=0), 0, 1)
    t = np.arange(200)[:, None] * np.array([1 / 30, 1 / 60])  # s
    return max(float(np.abs(a.step(x[i], t[i]) - b.step(x[i], t[i])).max()) for i in range(200))
