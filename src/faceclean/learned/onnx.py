"""The learned cleaner run by ONNX Runtime, from an exported step graph (learned/export.py).

The graph holds one step with its state as explicit inputs and outputs; this class keeps
that state between calls and applies the time rules of filters/base.py around it, so it
is interchangeable with the numpy runtime (``learned.lstm.Learned``).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from faceclean import strict_json
from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.filters.base import MAX_GAP, State, StreamCleaner, gap_seconds
from faceclean.learned.formats import STEP as STEP_FORMAT


def _session(model: bytes, threads: int, label: str) -> Any:
    try:
        import onnxruntime as ort
    except ImportError:
        raise FacecleanError(
            "the ONNX backend needs onnxruntime (pip install onnxruntime)"
        ) from None
    _no_external_data(model, label)
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3  # errors only
    with tempfile.TemporaryDirectory(prefix="faceclean-onnx-") as empty:
        # A graph from bytes finds external data in the current folder: look in an empty
        # one instead, so that a tensor stored outside the .onnx is never read from disk
        # (onnxruntime >= 1.21; _no_external_data refuses it first where onnx is installed)
        opts.add_session_config_entry(_DATA_FOLDER, empty)
        try:
            return ort.InferenceSession(model, opts, providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own types for a bad graph
            if "external data" in str(e).lower():
                raise FacecleanError(f"{label}: {EXTERNAL_DATA}") from None
            first = str(e).splitlines()[0]
            raise FacecleanError(f"not a loadable ONNX model ({first})") from None


_DATA_FOLDER = "session.model_external_initializers_file_folder_path"
EXTERNAL_DATA = (
    "its tensors are in external data files, which faceclean does not read (they could be "
    "anywhere); give a self-contained .onnx (faceclean export writes one; or "
    "onnx.save_model(model, path, save_as_external_data=False))"
)


def _no_external_data(model: bytes, label: str) -> None:
    """Refuse a graph with a tensor stored outside its bytes (onnx, where installed)."""
    try:
        import onnx
        from onnx import external_data_helper
    except ImportError:
        return  # the session's empty data folder refuses it instead
    try:
        proto = onnx.load_model_from_string(model, load_external_data=False)
    except Exception:
        return  # not a model: the session says so
    if any(external_data_helper.uses_external_data(t) for t in _tensors(proto.graph)):
        raise FacecleanError(f"{label}: {EXTERNAL_DATA}")


def _tensors(graph) -> Any:
    """Every tensor of an ONNX graph: its initializers, and its nodes' tensor attributes,
    subgraphs included (onnx's public fields, not its private walker)."""
    yield from graph.initializer
    for node in graph.node:
        for a in node.attribute:
            if a.HasField("t"):
                yield a.t
            yield from a.tensors
            for g in (*([a.g] if a.HasField("g") else []), *a.graphs):
                yield from _tensors(g)


def model_bytes(path: str | os.PathLike) -> bytes:
    """The step graph of ``path``: an exported .onnx as is, or a .npz checkpoint built now."""
    from faceclean.io.source import read_bytes
    from faceclean.learned.formats import MAX_MODEL_BYTES, model_file

    p = model_file(path)  # a FIFO or folder: one true line
    if p.suffix.lower() == ".npz":
        from faceclean.learned.checkpoint import LSTMWeights
        from faceclean.learned.export import build  # needs onnx, not torch

        return build(LSTMWeights.load(p)).SerializeToString()
    return read_bytes(p, MAX_MODEL_BYTES, "model file")


class OnnxLearned(StreamCleaner):
    """The learned cleaner on ONNX Runtime; ``path``: a .onnx step graph, a .npz model, or
    the graph's bytes.

    Channels map onto ``names`` as in ``Learned`` (extra inputs pass through).
    """

    name = "lstm-onnx"

    def __init__(
        self,
        path: str | os.PathLike | bytes,
        *,
        names: Sequence[str] = ARKIT52,
        max_gap: float = MAX_GAP,
        threads: int = 1,
    ) -> None:
        graph = path if isinstance(path, bytes) else model_bytes(path)
        label = "model" if isinstance(path, bytes) else Path(path).name
        self.session = _session(graph, threads, label)
        meta = self.session.get_modelmeta().custom_metadata_map
        if meta.get("faceclean.format") != STEP_FORMAT:
            raise FacecleanError(f"{label}: not a faceclean step graph ({STEP_FORMAT})")
        try:
            channels, config, state = (
                strict_json.loads(meta[k], f"{label}: {k}") for k in ("channels", "config", "state")
            )
            if not isinstance(channels, list) or not all(isinstance(c, str) for c in channels):
                raise ValueError("channels must be a list of names")
            if not isinstance(config, dict) or not isinstance(state, list):
                raise ValueError("config must be an object and state a list")
            self.channels, self.config = tuple(channels), config
            self.state_names = tuple(str(s) for s in state)
        except (KeyError, ValueError) as e:
            raise FacecleanError(f"{label}: bad faceclean metadata ({e})") from None
        self.max_gap = gap_seconds(max_gap)
        self.names = tuple(names)
        self.map = ChannelMap(self.channels, self.names)
        widths = {i.name: i.shape[1] for i in self.session.get_inputs()}
        self._widths = [int(widths[n]) for n in self.state_names]
        self._outputs = [f"{n}_next" for n in self.state_names]
        self.reset()

    @property
    def state_bytes(self) -> int:
        """Bytes of recurrent state per stream (float32)."""
        return 4 * sum(self._widths)

    def _start(self, x: np.ndarray) -> State:
        S = x.shape[0]
        state = [np.zeros((S, w), np.float32) for w in self._widths]
        self.map.gather(x, state[0], state[0])  # y = the first frame; the rest 0
        return tuple(state)

    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        x_new = np.empty_like(state[0])
        self.map.gather(x, state[0], x_new)
        feeds = dict(zip(self.state_names, state, strict=True))
        feeds["x_new"] = x_new
        feeds["dt"] = dt.astype(np.float32)
        new = tuple(self.session.run(self._outputs, feeds))
        return new, self.map.scatter(x, new[0])
