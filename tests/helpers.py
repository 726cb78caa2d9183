"""Helpers the test packages share (plain functions; the fixtures are in conftest.py).

tests/ mirrors src/faceclean/: tests/io/ tests io/, tests/learned/ tests learned/, and so
on; the top-level modules (adjust, calibration, resolve, the facade) and whole-product
suites (the cleaner contract over every backend, the red team, hostile generated cases,
the architecture, the install) sit in tests/ itself. tests/conftest.py puts this folder on
sys.path (pytest's rootdir conftest), so any test imports ``from helpers import ...``.
"""

from __future__ import annotations

import contextlib
import signal
import socket
from pathlib import Path

import numpy as np
import pytest

from faceclean.channels import INDEX
from faceclean.settings import data_dir

REPO = Path(__file__).resolve().parents[1]  # the repository root
IMPORTERS = REPO / "tests" / "importers"  # the real glTF importers the tests drive


def not_installed(package: str) -> str:
    """A prelude for `python -c`: ``package`` as if not installed (a finder that refuses it)."""
    return f"""
import sys
class _NotInstalled:
    def find_spec(self, name, path=None, target=None):
        if name == {package!r} or name.startswith({package + "."!r}):
            raise ImportError("{package} is not installed (test)")
sys.meta_path.insert(0, _NotInstalled())
"""


NOT_INSTALLED = not_installed("torch")


def steps(cleaner, t, x) -> np.ndarray:
    """(N, M) outputs of stepping ``cleaner`` frame by frame over (N,) times, (N, M) values."""
    return np.array([cleaner.step(x[i], t[i]) for i in range(len(t))])


def irregular(n: int, fps: float = 60.0, seed: int = 0, spread=(0.5, 1.5)) -> np.ndarray:
    """(n,) increasing times s: frame intervals drawn uniformly in spread x 1/fps."""
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.uniform(spread[0], spread[1], n) / fps)


def arkit_weights(**channels: float) -> np.ndarray:
    """(52,) ARKit weights: zero but for the named channels."""
    w = np.zeros(52)
    for name, value in channels.items():
        w[INDEX[name]] = value
    return w


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A loopback port free right now (UDP by default)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def shared(*parts: str) -> Path:
    """A path under ../shared/data, or skip the test saying which file is absent."""
    root = data_dir()
    path = None if root is None else root.joinpath(*parts)
    if path is None or not path.exists():
        pytest.skip(f"shared data ({'/'.join(parts)}) not present")
    return path


def first_take(source: str) -> Path:
    """The first take (by name) of a source folder under ../shared/data/arkit_takes."""
    return sorted(shared("arkit_takes", source).glob("*.csv"))[0]


def gltf_doc(uri: str) -> tuple[dict, bytes]:
    """A minimal .gltf document (one jawOpen weight track, 4 keys) whose one buffer of
    4 float32 times and 4 weights lives at ``uri``, and that buffer's bytes."""
    data = np.array([0, 1, 2, 3], "<f4").tobytes() + np.full(4, 0.5, "<f4").tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(data), "uri": uri}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 16},
                        {"buffer": 0, "byteOffset": 16, "byteLength": 16}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "SCALAR"},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "SCALAR"}],
        "meshes": [{"primitives": [{"attributes": {}, "targets": [{}]}],
                    "extras": {"targetNames": ["jawOpen"]}}],
        "nodes": [{"mesh": 0}],
        "animations": [{"samplers": [{"input": 0, "output": 1}],
                        "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}],
    }  # fmt: skip
    return doc, data


@contextlib.contextmanager
def reaped(proc):
    """Kill the command ``proc`` on the way out if it still runs (a failing test never
    leaves one behind)."""
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def interrupt(proc, timeout: float = 30.0) -> tuple[str, str]:
    """Ctrl-C a running command and wait for it: (stdout, stderr)."""
    proc.send_signal(signal.SIGINT)
    return proc.communicate(timeout=timeout)
