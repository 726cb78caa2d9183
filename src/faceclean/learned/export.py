"""ONNX export of the learned cleaner: one causal step with every piece of state explicit.

The graph is built with ``onnx.helper`` straight from the checkpoint's arrays (the same
folded matrices as the numpy runtime, lstm_weights.Fused), so exporting needs the
``onnx`` package but not torch. The engine that runs it (ONNX Runtime, Unity Sentis,
Unreal NNE) owns the state: feed each step's ``*_next`` outputs back as the next inputs.

Inputs, S streams (the batch axis is dynamic), float32:
    x_new (S, M)   the new input frame, channels in metadata ``channels`` order
    dt    (S, 1)   seconds since the previous frame (> 0)
    y     (S, M)   last output x̂[n]            (start: the first frame, as is)
    d     (S, M)   last derivatives x̂'[n-1]    (start: 0)
    h{l}, c{l} (S, H) LSTM state of layer l     (start: 0)
Outputs: ``y_next`` (the cleaned frame, = the next ``y``), ``d_next``, ``h{l}_next``,
``c{l}_next``. Time rules (first frame, missing frames, gaps, repeated timestamps) are
the caller's, as in filters/base.py; faceclean's ONNX backend applies them.

Metadata (``metadata_props``): ``faceclean.format`` = faceclean-lstm-step/1,
``channels`` (JSON list), ``config`` (the checkpoint's JSON), ``feat_mean``,
``feat_std``, ``out_scale`` (JSON lists; already folded into the weights),
``state`` (JSON list of the state inputs in order).
"""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from faceclean.errors import FacecleanError
from faceclean.learned.checkpoint import RATE_A_MAX, RATE_TAU0, LSTMWeights
from faceclean.learned.formats import STEP as STEP_FORMAT

OPSET = 17


def _onnx() -> Any:
    try:
        import onnx
    except ImportError:
        raise FacecleanError("ONNX export needs the onnx package (pip install onnx)") from None
    return onnx


def state_names(layers: int) -> list[str]:
    """The state inputs in order: y, d, h0, c0, h1, c1, ..."""
    return ["y", "d"] + [f"{k}{i}" for i in range(layers) for k in ("h", "c")]


def build(weights: LSTMWeights) -> Any:
    """The single-step ``onnx.ModelProto`` of a checkpoint (see the module docstring)."""
    onnx = _onnx()
    from onnx import TensorProto, helper, numpy_helper

    if weights.K != 1:
        raise FacecleanError(f"export supports K = 1 models (this one: K = {weights.K})")
    M, H, L = len(weights.channels), weights.hidden, weights.layers
    fused = weights.fused()  # gates (i, f, o, g), scaling folded in; no 1/2 pre-scale
    inits, nodes = [], []

    def const(name: str, value: np.ndarray) -> str:
        inits.append(numpy_helper.from_array(np.ascontiguousarray(value), name))
        return name

    def node(op: str, inputs: list[str], output: str | list[str], **attrs: Any) -> str:
        outs = [output] if isinstance(output, str) else output
        nodes.append(helper.make_node(op, inputs, outs, name=outs[0], **attrs))
        return outs[0]

    f32 = np.float32
    lo, hi = (np.array(v, f32) for v in weights.value_range)
    node("Div", [node("Sub", ["x_new", "y"], "x_minus_y"), "dt"], "xc")  # Eq. 2
    u = node("Concat", ["y", "d", "xc"], "features", axis=1)  # (S, 3M), raw
    split = const("gate_split", np.full(4, H, np.int64))
    for i, w in enumerate(fused.layers):
        n_in = w.shape[0] - H - 1  # rows: [in | h | bias]
        gx = node("MatMul", [u, const(f"W{i}_x", w[:n_in])], f"gx{i}")
        gh = node("MatMul", [f"h{i}", const(f"W{i}_h", w[n_in:-1])], f"gh{i}")
        gates = node("Add", [node("Add", [gx, gh], f"gxh{i}"), const(f"b{i}", w[-1])], f"a{i}")
        gi, gf, go, gg = parts = [f"{g}{i}" for g in "ifog"]
        node("Split", [gates, split], parts, axis=1)
        si, sf, so = (node("Sigmoid", [g], f"sig_{g}") for g in (gi, gf, go))
        tg = node("Tanh", [gg], f"tanh_{gg}")
        fc = node("Mul", [sf, f"c{i}"], f"fc{i}")
        c_next = node("Add", [fc, node("Mul", [si, tg], f"ig{i}")], f"c{i}_next")
        h_next = node("Mul", [so, node("Tanh", [c_next], f"tanh_c{i}")], f"h{i}_next")
        u = h_next if i == 0 else node("Add", [h_next, u], f"res{i}")  # residual, l >= 1
    head = node("MatMul", [u, const("head_w", fused.head[:-1])], "head_mm")
    corr = node("Add", [head, const("head_b", fused.head[-1])], "correction")
    if weights.output != "additive":  # correction = [a | out_scale b], (S, 2M)
        halves = const("head_split", np.full(2, M, np.int64))
        a, b = "gain_logit", "gated_correction"
        node("Split", [corr, halves], [a, b], axis=1)
        one = const("one", np.array(1.0, f32))
        if weights.gated:
            gain = node("Add", [node("Tanh", [a], "tanh_a"), one], "gain")  # 1 + tanh a
        else:  # 1 - exp(-dt / tau), tau = RATE_TAU0 e^a
            a_max = np.array(RATE_A_MAX, f32)
            ac = node("Clip", [a, const("a_min", -a_max), const("a_max", a_max)], "a_clip")
            inv_tau = node("Exp", [node("Neg", [ac], "neg_a")], "inv_tau_rel")
            k = const("neg_inv_tau0", np.array(-1.0 / RATE_TAU0, f32))
            arg = node("Mul", [node("Mul", [inv_tau, "dt"], "dt_tau_rel"), k], "neg_dt_tau")
            gain = node("Sub", [one, node("Exp", [arg], "retain")], "gain")
        node("Add", [node("Mul", [gain, "xc"], "gain_xc"), b], "d_next")  # g x_c + b
    else:
        node("Add", ["xc", corr], "d_next")  # x̂'[n] = x_c + out_scale dense(h)
    step = node("Mul", ["dt", "d_next"], "dy")
    node("Clip", [node("Add", ["y", step], "y_raw"), const("lo", lo), const("hi", hi)], "y_next")

    def vi(name: str, width: int) -> Any:
        return helper.make_tensor_value_info(name, TensorProto.FLOAT, ["S", width])

    states = state_names(L)
    width = {"y": M, "d": M} | {s: H for s in states[2:]}
    inputs = [vi("x_new", M), vi("dt", 1)] + [vi(s, width[s]) for s in states]
    outputs = [vi(f"{s}_next", width[s]) for s in states]
    graph = helper.make_graph(
        nodes, "faceclean_lstm_step", inputs, outputs, inits, doc_string=__doc__.split("\n")[0]
    )
    model = helper.make_model(
        graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="faceclean"
    )
    model.ir_version = 8  # readable by older runtimes (ONNX Runtime >= 1.10)
    meta = {
        "faceclean.format": STEP_FORMAT,
        "channels": json.dumps(list(weights.channels)),
        "config": json.dumps(weights.config),
        "feat_mean": json.dumps(weights.feat_mean.tolist()),
        "feat_std": json.dumps(weights.feat_std.tolist()),
        "out_scale": json.dumps(weights.out_scale.tolist()),
        "state": json.dumps(states),
    }
    helper.set_model_props(model, meta)
    onnx.checker.check_model(model)
    return model


def export(model_path: str | os.PathLike, out: str | os.PathLike) -> dict[str, Any]:
    """Write the step graph of the checkpoint at ``model_path`` to ``out`` (atomically).

    Returns facts for the caller to print: channels, layers, hidden, bytes.
    """
    from faceclean.io.atomic import atomic_write
    from faceclean.learned.adaptive import is_adaptive

    if is_adaptive(model_path):
        raise FacecleanError(
            "ONNX export covers the LSTM step graph; the adaptive model (the shipped "
            "default) runs in faceclean's numpy runtime and relay, not yet as ONNX"
        )
    weights = LSTMWeights.load(model_path)
    data = build(weights).SerializeToString()
    atomic_write(out, data)
    return {
        "channels": len(weights.channels),
        "layers": weights.layers,
        "hidden": weights.hidden,
        "bytes": len(data),
    }
