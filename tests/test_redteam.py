"""Red team for issue 14: the command line and the relay attacked as a hostile user would.

Every case runs ``faceclean`` as a subprocess (black box: nothing is imported from
faceclean) on inputs generated into ``tmp_path``, under a memory cap (RLIMIT_AS) and a
wall-clock timeout, and asserts the right behaviour:

- bad input: exit 2 and one line ``faceclean: ...`` on stderr; never a traceback, an
  ``internal error`` or a numpy warning;
- no output half-written (no ``.*.tmp`` left), the input and whatever ``-o`` named
  untouched when the run is refused;
- nothing erased in silence: a cleaner's output is finite wherever its input was;
- memory and time bounded by the input, not by what a header or a flag claims;
- the relay survives every datagram: after the hostile packets, good frames still
  arrive cleaned at a receiver socket, and the process is alive.

A case that fails on today's code is ``xfail(strict=True)`` with the reason
``redteam: <class>: <what goes wrong>``; whoever fixes it removes the mark.
"""

from __future__ import annotations

import base64
import contextlib
import json
import math
import os
import resource
import signal
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
MiB = 1 << 20
MEM = 1024 * MiB  # address-space cap per run (a normal run needs well under half)
TIMEOUT = 90.0  # s, per run, for cases that are not about time
HANG = 20.0  # s, for cases that are about time (a right answer takes ~1 s)

# ARKit's 52 blendshapes, canonical order (a published constant, not faceclean's code).
ARKIT = [
    "eyeBlinkLeft",
    "eyeLookDownLeft",
    "eyeLookInLeft",
    "eyeLookOutLeft",
    "eyeLookUpLeft",
    "eyeSquintLeft",
    "eyeWideLeft",
    "eyeBlinkRight",
    "eyeLookDownRight",
    "eyeLookInRight",
    "eyeLookOutRight",
    "eyeLookUpRight",
    "eyeSquintRight",
    "eyeWideRight",
    "jawForward",
    "jawLeft",
    "jawRight",
    "jawOpen",
    "mouthClose",
    "mouthFunnel",
    "mouthPucker",
    "mouthLeft",
    "mouthRight",
    "mouthSmileLeft",
    "mouthSmileRight",
    "mouthFrownLeft",
    "mouthFrownRight",
    "mouthDimpleLeft",
    "mouthDimpleRight",
    "mouthStretchLeft",
    "mouthStretchRight",
    "mouthRollLower",
    "mouthRollUpper",
    "mouthShrugLower",
    "mouthShrugUpper",
    "mouthPressLeft",
    "mouthPressRight",
    "mouthLowerDownLeft",
    "mouthLowerDownRight",
    "mouthUpperUpLeft",
    "mouthUpperUpRight",
    "browDownLeft",
    "browDownRight",
    "browInnerUp",
    "browOuterUpLeft",
    "browOuterUpRight",
    "cheekPuff",
    "cheekSquintLeft",
    "cheekSquintRight",
    "noseSneerLeft",
    "noseSneerRight",
    "tongueOut",
]
PASCAL = [n[0].upper() + n[1:] for n in ARKIT]
ANGLES = [
    "HeadYaw",
    "HeadPitch",
    "HeadRoll",
    "LeftEyeYaw",
    "LeftEyePitch",
    "LeftEyeRoll",
    "RightEyeYaw",
    "RightEyePitch",
    "RightEyeRoll",
]
assert len(ARKIT) == 52


def fail(reason: str):
    """The mark of a case that fails on today's code (a fix turns it into XPASS)."""
    return pytest.mark.xfail(strict=True, reason=f"redteam: {reason}")


# --------------------------------------------------------------------------------------
# Running the command


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "FACECLEAN_DEBUG"}
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "src"), env.get("PYTHONPATH", "")])
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    env.update(NUMBA_NUM_THREADS="1", PYTHONWARNINGS="default", LC_ALL="C.UTF-8")
    env.pop("PYTHONIOENCODING", None)
    return env


def _limits(mem: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
        os.setsid()  # its own group: a timeout kills it and its children

    return apply


def fc(*args, timeout: float = TIMEOUT, mem: int = MEM, cwd=None, stdin=None):
    """Run ``faceclean ARGS`` -> CompletedProcess (text out/err); None when it timed out."""
    cmd = [sys.executable, "-m", "faceclean", *[os.fsdecode(a) for a in args]]
    proc = subprocess.Popen(
        cmd,
        cwd=cwd or REPO,
        env=_env(),
        stdin=stdin if stdin is not None else subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=_limits(mem),
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return None
    return subprocess.CompletedProcess(
        cmd, proc.returncode, out.decode("utf-8", "replace"), err.decode("utf-8", "replace")
    )


BAD_STDERR = ("Traceback", "internal error", "Warning", "warning:", "Error:")


def clean_stderr(err: str) -> None:
    for bad in BAD_STDERR:
        assert bad not in err, f"stderr shows {bad!r}: {err[-600:]}"


def refused(r) -> None:
    """Exit 2 with one line a user can act on."""
    assert r is not None, "no exit before the timeout (hang)"
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert r.returncode == 2, f"exit {r.returncode}: {r.stderr[-600:]}"
    assert len(lines) == 1, f"not one line: {r.stderr[-600:]}"
    assert lines[0].startswith("faceclean: "), lines[0]
    assert len(lines[0]) < 400, lines[0]
    clean_stderr(r.stderr)


def ok(r) -> None:
    assert r is not None, "no exit before the timeout (hang)"
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr[-600:]}"
    clean_stderr(r.stderr)


def ok_or_refused(r) -> bool:
    """Either is right; True when it ran (exit 0)."""
    assert r is not None, "no exit before the timeout (hang)"
    if r.returncode == 0:
        clean_stderr(r.stderr)
        return True
    refused(r)
    return False


def no_temp_files(folder: Path) -> None:
    left = [p.name for p in folder.iterdir() if p.name.endswith(".tmp")]
    assert not left, f"temporary files left: {left}"


# --------------------------------------------------------------------------------------
# Inputs, generated (small)


def curves(n: int = 40, m: int = 52, seed: int = 0) -> np.ndarray:
    """(n, m) smooth weights in [0.1, 0.9] plus a little jitter."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None] / 60.0
    phase = rng.uniform(0, 2 * np.pi, m)
    x = 0.5 + 0.35 * np.sin(2 * np.pi * 0.7 * t + phase) + rng.normal(0, 0.02, (n, m))
    return np.clip(x, 0.1, 0.9)


def timecode(seconds: float) -> str:
    sub = round(seconds * 60000)
    frame, frac = divmod(sub, 1000)
    sec, ff = divmod(frame, 60)
    h, rest = divmod(sec, 3600)
    mi, s = divmod(rest, 60)
    return f"{h % 24:02d}:{mi:02d}:{s:02d}:{ff:02d}.{frac:03d}"


def livelink_text(n: int = 40, start: float = 60530.0, values=None, stamps=None) -> bytes:
    """A Live Link Face CSV: header, n rows of 52 blendshapes + 9 angles."""
    x = curves(n) if values is None else values
    head = ",".join(["Timecode", "BlendshapeCount", *PASCAL, *ANGLES])
    rows = [head]
    for i in range(len(x)):
        tc = stamps[i] if stamps is not None else timecode(start + i / 60.0)
        cells = [f"{v:.10f}" for v in x[i]] + ["0.0100000000"] * 9
        rows.append(",".join([tc, "61", *cells]))
    return ("\n".join(rows) + "\n").encode()


def plain_text(n: int = 40, names=ARKIT, values=None, times=None) -> bytes:
    x = curves(n, len(names)) if values is None else values
    t = np.arange(len(x)) / 60.0 if times is None else times
    rows = [",".join(["time", *names])]
    for i in range(len(x)):
        rows.append(",".join([repr(float(t[i])), *(repr(float(v)) for v in x[i])]))
    return ("\n".join(rows) + "\n").encode()


def json_doc(n: int = 40, names=ARKIT, values=None) -> dict:
    x = curves(n, len(names)) if values is None else values
    return {
        "format": "faceclean-animation/1",
        "channels": list(names),
        "times": (np.arange(len(x)) / 60.0).tolist(),
        "values": np.asarray(x).tolist(),
    }


def write_json(path: Path, doc) -> Path:
    path.write_text(json.dumps(doc))
    return path


def npz_arrays(n: int = 40, names=ARKIT) -> dict:
    return {
        "format": np.array("faceclean-animation/1"),
        "times": np.arange(n) / 60.0,
        "values": curves(n, len(names)),
        "names": np.array(names),
    }


def write_npz(path: Path, arrays: dict) -> Path:
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


def gltf_parts(n: int = 20, m: int = 4, names=None):
    """(doc, bin) of a minimal glTF: one mesh with m morph targets, one weight animation."""
    times = (np.arange(n) / 30.0).astype("<f4")
    weights = curves(n, m).astype("<f4")
    pos = np.zeros((3, 3), "<f4")
    blobs = [pos.tobytes(), times.tobytes(), weights.tobytes()]
    views, offset = [], 0
    for b in blobs:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(b)})
        offset += len(b)
    data = b"".join(blobs)
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(data)}],
        "bufferViews": views,
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
            {
                "bufferView": 1,
                "componentType": 5126,
                "count": n,
                "type": "SCALAR",
                "min": [0.0],
                "max": [float(times[-1])],
            },
            {"bufferView": 2, "componentType": 5126, "count": n * m, "type": "SCALAR"},
        ],  # fmt: skip
        "meshes": [
            {
                "primitives": [{"attributes": {"POSITION": 0}, "targets": [{"POSITION": 0}] * m}],
                "extras": {"targetNames": list(names or ARKIT[:m])},
            }
        ],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "animations": [
            {
                "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
                "samplers": [{"input": 1, "output": 2, "interpolation": "LINEAR"}],
            }
        ],
    }
    return doc, data


def glb_bytes(doc: dict, data: bytes | None) -> bytes:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if data is not None:
        data = data + b"\0" * (-len(data) % 4)
        chunks += struct.pack("<II", len(data), 0x004E4942) + data
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def write_glb(path: Path, doc=None, data=None, **kw) -> Path:
    if doc is None:
        doc, data = gltf_parts(**kw)
    path.write_bytes(glb_bytes(doc, data))
    return path


def write_gltf(path: Path, doc: dict, data: bytes) -> Path:
    doc = json.loads(json.dumps(doc))
    doc["buffers"][0]["uri"] = (
        "data:application/octet-stream;base64," + base64.b64encode(data).decode()
    )
    path.write_text(json.dumps(doc))
    return path


def read_plain(path: Path) -> tuple[list[str], np.ndarray]:
    """(header, (N, C) float table with NaN for empty cells) of a plain CSV."""
    lines = path.read_text().splitlines()
    head = lines[0].split(",")
    rows = [[float(c) if c.strip() else math.nan for c in line.split(",")] for line in lines[1:]]
    return head, np.array(rows)


def read_livelink_values(path: Path) -> np.ndarray:
    """(N, 52) blendshape values of a Live Link CSV (NaN for missing rows)."""
    lines = path.read_text().splitlines()
    head = lines[0].split(",")
    cols = [head.index(n) for n in PASCAL]
    out = []
    for line in lines[1:]:
        f = line.split(",")
        out.append([float(f[j]) if len(f) > 2 else math.nan for j in cols])
    return np.array(out)


def finite_where_input_was(inp: np.ndarray, out: np.ndarray) -> None:
    assert inp.shape == out.shape, (inp.shape, out.shape)
    lost = np.isfinite(inp) & ~np.isfinite(out)
    assert not lost.any(), f"{int(lost.sum())} of {int(np.isfinite(inp).sum())} finite cells erased"


@pytest.fixture
def take(tmp_path) -> Path:
    p = tmp_path / "take.csv"
    p.write_bytes(livelink_text())
    return p


@pytest.fixture
def plain(tmp_path) -> Path:
    p = tmp_path / "plain.csv"
    p.write_bytes(plain_text())
    return p


# --------------------------------------------------------------------------------------
# A. --set values a careless or hostile user types (clean, streaming Live Link path)

DEEP = "[" * 100_000 + "]" * 100_000

SET_REFUSED = [
    pytest.param("one-euro", "min_cutoff=1e999", id="inf-by-overflow"),
    pytest.param("one-euro", "min_cutoff=NaN", id="nan"),
    pytest.param("one-euro", "min_cutoff=Infinity", id="infinity"),
    pytest.param("one-euro", "min_cutoff=-Infinity", id="minus-infinity"),
    pytest.param("one-euro", "min_cutoff=-1", id="negative"),
    pytest.param("one-euro", "min_cutoff=0", id="zero-cutoff"),
    pytest.param(
        "one-euro",
        "min_cutoff=" + "9" * 400,
        id="huge-int",
        marks=fail("internal error: a 400-digit integer overflows float (OverflowError)"),
    ),
    pytest.param(
        "one-euro",
        "min_cutoff=" + DEEP,
        id="deep-nesting",
        marks=fail("internal error: 100k nested JSON lists (RecursionError)"),
    ),
    pytest.param("one-euro", "min_cutoff=[[1.0]]", id="2d-list"),
    pytest.param("one-euro", "min_cutoff=[1.0, 2.0]", id="wrong-length"),
    pytest.param("one-euro", 'min_cutoff={"a": 1}', id="object"),
    pytest.param("one-euro", "min_cutoff=true", id="boolean"),
    pytest.param("one-euro", "min_cutoff=null", id="null"),
    pytest.param("one-euro", "min_cutoff=", id="empty"),
    pytest.param("one-euro", "min_cutoff=abc", id="word"),
    pytest.param("one-euro", "no_such_param=1", id="unknown-key"),
    pytest.param("one-euro", "names=[1]", id="names-key"),
    pytest.param("one-euro", "=1", id="no-key"),
    pytest.param("one-euro", "min_cutoff", id="no-equals"),
    pytest.param("one-euro", "min_cutoff=" + json.dumps([1.0] * 51 + [math.nan]), id="list-nan"),
    pytest.param("kalman", "r=-1e-300", id="kalman-negative-r"),
    pytest.param("ema", "tau=-5", id="ema-negative-tau"),
    pytest.param("lstm", "max_gap=NaN", id="lstm-nan-gap"),
    pytest.param("lstm", "max_gap=-1", id="lstm-negative-gap"),
    pytest.param("lstm", 'kernel="gpu"', id="lstm-bad-kernel"),
    pytest.param("lstm", "path=/etc/passwd", id="lstm-model-not-npz"),
    pytest.param("lstm", "path=/nonexistent/model.npz", id="lstm-model-missing"),
    pytest.param("no-such-method", "x=1", id="unknown-method"),
    pytest.param("savgol", "polyorder=-1", id="savgol-negative-order"),
    pytest.param("savgol", "window_frames=2.5", id="savgol-fractional-window"),
]


@pytest.mark.parametrize(("method", "item"), SET_REFUSED)
def test_set_value_is_refused(tmp_path, take, method, item):
    out = tmp_path / "out.csv"
    before = take.read_bytes()
    refused(fc("clean", take, "-o", out, "--method", method, "--set", item))
    assert not out.exists()
    assert take.read_bytes() == before
    no_temp_files(tmp_path)


SET_FINITE = [
    pytest.param(
        "kalman",
        "r=1e300",
        id="kalman-r-1e300",
        marks=fail("silent loss: kalman r=1e300 writes a file with every changed cell NaN"),
    ),
    pytest.param("kalman", "q=1e300", id="kalman-q-1e300"),
    pytest.param("kalman", "q=1e-300", id="kalman-q-tiny"),
    pytest.param("kalman", "r=1e-300", id="kalman-r-tiny"),
    pytest.param(
        "one-euro",
        "beta=1e308",
        id="one-euro-beta-1e308",
        marks=fail("wrong answer: numpy RuntimeWarning (overflow) from one_euro.py on stderr"),
    ),
    pytest.param("one-euro", "min_cutoff=1e-300", id="one-euro-cutoff-tiny"),
    pytest.param(
        "one-euro",
        "min_cutoff=1e308",
        id="one-euro-cutoff-huge",
        marks=fail("wrong answer: numpy RuntimeWarning (overflow) from one_euro.py on stderr"),
    ),
    pytest.param(
        "one-euro",
        "d_cutoff=1e308",
        id="one-euro-dcutoff-huge",
        marks=fail("wrong answer: numpy RuntimeWarning (overflow) from one_euro.py on stderr"),
    ),
    pytest.param("one-euro", "d_cutoff=1e-300", id="one-euro-dcutoff-tiny"),
    pytest.param("ema", "tau=1e-300", id="ema-tau-tiny"),
    pytest.param("ema", "tau=1e300", id="ema-tau-huge"),
    pytest.param("lstm", "max_gap=1e308", id="lstm-gap-huge"),
    pytest.param("gaussian", "sigma=1e300", id="gaussian-sigma-huge"),
    pytest.param("gaussian", "sigma_frames=1e9", id="gaussian-sigma-frames-huge"),
    pytest.param("savgol", "window=1e300", id="savgol-window-huge"),
    pytest.param("savgol", "window_frames=1000000000000000000", id="savgol-window-frames-huge"),
    pytest.param("savgol", "polyorder=1000", id="savgol-order-huge"),
]


@pytest.mark.parametrize(("method", "item"), SET_FINITE)
def test_set_extreme_value_never_erases_data(tmp_path, plain, method, item):
    """A finite but absurd parameter: refused, or a finite output; never NaN cells."""
    out = tmp_path / "out.csv"
    r = fc("clean", plain, "-o", out, "--method", method, "--set", item)
    if ok_or_refused(r):
        finite_where_input_was(read_plain(plain)[1], read_plain(out)[1])
    else:
        assert not out.exists()
    no_temp_files(tmp_path)


# --------------------------------------------------------------------------------------
# B. Preset files


def preset(tmp_path: Path, body: str | bytes, name: str = "p.json") -> Path:
    p = tmp_path / name
    p.write_bytes(body.encode() if isinstance(body, str) else body)
    return p


def _preset_doc(**kw) -> str:
    doc = {"format": "faceclean-preset/1", "method": "one-euro", "params": {"min_cutoff": 1.0}}
    doc.update(kw)
    return json.dumps(doc)


PRESET_REFUSED = [
    pytest.param("not json", id="not-json"),
    pytest.param("[1, 2]", id="array"),
    pytest.param(b"\xff\xfe\x00garbage", id="not-utf8"),
    pytest.param("{" * 50_000 + "}" * 50_000, id="deep-objects"),
    pytest.param(
        '{"format": "faceclean-preset/1", "method": "one-euro", "params": ' + DEEP[:20000] + "}",
        id="deep-params",
    ),  # fmt: skip
    pytest.param(
        _preset_doc(params={"min_cutoff": 10**400}),
        id="huge-int",
        marks=fail("internal error: preset int 10**400 (OverflowError in math.isfinite)"),
    ),
    pytest.param(
        _preset_doc(groups={"eyes": {"min_cutoff": 10**400}}),
        id="huge-int-group",
        marks=fail("internal error: preset group int 10**400 (OverflowError)"),
    ),
    pytest.param(
        _preset_doc(method=["one-euro"]),
        id="method-list",
        marks=fail("internal error: preset method is a list (unhashable TypeError)"),
    ),
    pytest.param(
        _preset_doc(method={"a": 1}),
        id="method-object",
        marks=fail("internal error: preset method is an object (unhashable TypeError)"),
    ),
    pytest.param(_preset_doc(method="lstm-x"), id="method-unknown"),
    pytest.param(_preset_doc(params={"min_cutoff": float("nan")}), id="nan"),
    pytest.param(_preset_doc(params={"min_cutoff": float("inf")}), id="infinity"),
    pytest.param(_preset_doc(params={"min_cutoff": "1.0"}), id="string-number"),
    pytest.param(_preset_doc(params={"min_cutoff": -3}), id="negative"),
    pytest.param(_preset_doc(params={"warp": 1}), id="unknown-param"),
    pytest.param(_preset_doc(params=[1, 2]), id="params-list"),
    pytest.param(_preset_doc(groups={"eyelids": {"beta": 1}}), id="unknown-group"),
    pytest.param(_preset_doc(groups=[["eyes"]]), id="groups-list-of-lists"),
    pytest.param(_preset_doc(groups={"eyes": {"beta": 1.0}}, params={}), id="group-only-param"),
    pytest.param(_preset_doc(about="me"), id="about-string"),
    pytest.param(_preset_doc(format=1), id="format-number"),
    pytest.param(_preset_doc(extra=1), id="unknown-key"),
]


@pytest.mark.parametrize("body", PRESET_REFUSED)
def test_preset_is_refused(tmp_path, take, body):
    p = preset(tmp_path, body)
    out = tmp_path / "out.csv"
    refused(fc("clean", take, "-o", out, "--preset", p))
    assert not out.exists()


@fail("silent loss: a kalman preset with r=1e308 erases 97% of the cells, exit 0")
def test_preset_kalman_r_1e308_never_erases_data(tmp_path, plain):
    p = preset(tmp_path, json.dumps({"format": "faceclean-preset/1", "method": "kalman",
                                     "params": {"q": 5.0, "r": 1e308}}))  # fmt: skip
    out = tmp_path / "out.csv"
    if ok_or_refused(fc("clean", plain, "-o", out, "--preset", p)):
        finite_where_input_was(read_plain(plain)[1], read_plain(out)[1])


def test_preset_that_is_a_fifo_does_not_hang(tmp_path, take):
    fifo = tmp_path / "p.json"
    os.mkfifo(fifo)
    refused(fc("clean", take, "-o", tmp_path / "o.csv", "--preset", fifo, timeout=HANG))


def test_preset_with_method_too_is_refused(tmp_path, take):
    p = preset(tmp_path, _preset_doc())
    refused(fc("clean", take, "-o", tmp_path / "o.csv", "--preset", p, "--method", "ema"))


# --------------------------------------------------------------------------------------
# C. Live Link Face CSV: both readers (in memory: info; in blocks: clean --method ema)


def _ll_rows(n: int = 8) -> list[bytes]:
    return livelink_text(n).split(b"\n")


def _ll_with(row: int, field: int, text: bytes, n: int = 8) -> bytes:
    lines = _ll_rows(n)
    cells = lines[row].split(b",")
    cells[field] = text
    lines[row] = b",".join(cells)
    return b"\n".join(lines)


LL_REFUSED = {
    "empty": b"",
    "header-only": _ll_rows()[0] + b"\n",
    "no-blendshape-columns": b"Timecode,BlendshapeCount,Foo,Bar\n00:00:00:00.000,2,1,2\n",
    "truncated-row": livelink_text(8)[:-300],
    "extra-field": b"\n".join(_ll_rows()[:3] + [_ll_rows()[3] + b",0.5"] + _ll_rows()[4:]),
    "header-not-utf8": b"Timecode,BlendshapeCount,JawOpen\xff,EyeBlinkLeft\n"
    b"00:00:00:00.000,2,1,2\n",
    "cell-not-utf8": _ll_with(2, 5, b"0.\xff5"),
    "cell-nul-inside": _ll_with(2, 5, b"0.\x005"),
    "cell-hex-float": _ll_with(2, 5, b"0x1p-2"),
    "cell-word": _ll_with(2, 5, b"half"),
    "timecode-word": _ll_with(2, 0, b"hello"),
    "timecode-negative": _ll_with(2, 0, b"-01:00:00:00.000"),
    "timecode-99": _ll_with(2, 0, b"99:99:99:99.999"),
    "timecode-frame-75": _ll_with(2, 0, b"16:48:50:75.000"),
    "timecode-minute-60": _ll_with(2, 0, b"16:60:50:05.000"),
    "timecode-hours-400-digits": _ll_with(2, 0, b"9" * 400 + b":00:00:00.000"),
    "timecode-hours-5000-digits": _ll_with(2, 0, b"9" * 5000 + b":00:00:00.000"),
    "timecode-frame-400-digits": _ll_with(2, 0, b"16:48:50:" + b"9" * 400),
}
LL_FAILS = {
    (
        "timecode-99",
        "info",
    ): "wrong answer: timecode 99:99:99:99.999 accepted (a fake midnight wrap)",
    (
        "timecode-99",
        "stream",
    ): "wrong answer: timecode 99:99:99:99.999 accepted (a fake midnight wrap)",
    ("timecode-frame-75", "info"): "wrong answer: frame 75 of a 60 fps timecode accepted",
    ("timecode-frame-75", "stream"): "wrong answer: frame 75 of a 60 fps timecode accepted",
    ("timecode-minute-60", "info"): "wrong answer: minute 60 in a timecode accepted",
    ("timecode-minute-60", "stream"): "wrong answer: minute 60 in a timecode accepted",
    (
        "timecode-99",
        "convert",
    ): "wrong answer: timecode 99:99:99:99.999 accepted (a fake midnight wrap)",
    ("timecode-frame-75", "convert"): "wrong answer: frame 75 of a 60 fps timecode accepted",
    ("timecode-minute-60", "convert"): "wrong answer: minute 60 in a timecode accepted",
    (
        "timecode-hours-400-digits",
        "stream",
    ): "internal error: the block reader lets OverflowError out (in memory: refused)",
    (
        "timecode-hours-5000-digits",
        "stream",
    ): "internal error: int digit limit ValueError in the block reader (in memory: refused)",
    (
        "timecode-frame-400-digits",
        "stream",
    ): "wrong answer: the block reader takes an infinite frame time, exit 0 (in memory: refused)",
}


def _ll_cases():
    for name in LL_REFUSED:
        for how in ("info", "stream", "convert"):
            reason = LL_FAILS.get((name, how))
            marks = [fail(reason)] if reason else []
            yield pytest.param(name, how, id=f"{name}-{how}", marks=marks)


def _run_reader(how: str, src: Path, tmp_path: Path):
    if how == "info":
        return fc("info", src)
    if how == "stream":  # ema is causal: the constant-memory block path
        return fc("clean", src, "-o", tmp_path / "out.csv", "--method", "ema")
    return fc("convert", src, "-o", tmp_path / "out.json")


@pytest.mark.parametrize(("name", "how"), list(_ll_cases()))
def test_livelink_malformed_is_refused_by_every_reader(tmp_path, name, how):
    src = tmp_path / "take.csv"
    src.write_bytes(LL_REFUSED[name])
    refused(_run_reader(how, src, tmp_path))
    assert not (tmp_path / "out.csv").exists() and not (tmp_path / "out.json").exists()
    assert src.read_bytes() == LL_REFUSED[name]
    no_temp_files(tmp_path)


LL_ODD_CELLS = ["inf", "-inf", "nan", "1e308", "-1e308", "1e-320", "-0.0", "1e30"]


@pytest.mark.parametrize("cell", LL_ODD_CELLS)
@pytest.mark.parametrize("method", ["lstm", "one-euro", "kalman"])
def test_livelink_odd_cell_never_erases_other_cells(tmp_path, cell, method):
    """One absurd cell: every finite input cell comes out finite (plain CSV shows NaN)."""
    src = tmp_path / "take.csv"
    src.write_bytes(_ll_with(5, 20, cell.encode(), n=30))
    out = tmp_path / "out.csv"
    r = fc("clean", src, "-o", out, "--method", method, "--format", "csv")
    if ok_or_refused(r):
        head, table = read_plain(out)
        x = read_livelink_values(src)
        finite_where_input_was(x, table[:, [head.index(n) for n in PASCAL]])


@fail("leak: info on a 1.5 MB take with one 10 KB cell allocates 1.1 GiB (MemoryError, exit 1)")
def test_livelink_one_huge_cell_reads_in_bounded_memory(tmp_path):
    """A 1.5 MB take with one 10 KB cell (a valid number) must not need gigabytes."""
    src = tmp_path / "take.csv"
    src.write_bytes(_ll_with(3, 7, b"0." + b"0" * 10_000 + b"5", n=2000))
    assert src.stat().st_size < 2 * MiB
    ok(fc("info", src, mem=MEM))


@fail("leak: the constant-memory clean path allocates 1.1 GiB for one 10 KB cell")
def test_livelink_one_huge_cell_streams_in_bounded_memory(tmp_path):
    src = tmp_path / "take.csv"
    src.write_bytes(_ll_with(3, 7, b"0." + b"0" * 10_000 + b"5", n=2000))
    ok(fc("clean", src, "-o", tmp_path / "out.csv", "--method", "ema", mem=MEM))


def test_livelink_stream_and_memory_agree_on_a_backwards_midnight(tmp_path):
    """Rows that step back 13 h are a midnight wrap for both readers: same times out."""
    stamps = [timecode(86400 - 1 + i / 60) for i in range(6)]  # 23:59:59 -> 00:00:00
    src = tmp_path / "take.csv"
    src.write_bytes(livelink_text(6, stamps=stamps))
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    ok(fc("clean", src, "-o", a, "--method", "ema"))  # streamed
    ok(fc("clean", src, "-o", b, "--method", "ema", "--format", "livelink"))
    assert a.read_bytes() == b.read_bytes()


# --------------------------------------------------------------------------------------
# D. Plain CSV


def _plain_with(row: int, field: int, text: bytes, n: int = 8) -> bytes:
    lines = plain_text(n).split(b"\n")
    cells = lines[row].split(b",")
    cells[field] = text
    lines[row] = b",".join(cells)
    return b"\n".join(lines)


PLAIN_REFUSED = {
    "no-time-column": b"jawOpen,eyeBlinkLeft\n0.1,0.2\n",
    "time-inf": _plain_with(3, 0, b"inf"),
    "time-minus-inf": _plain_with(3, 0, b"-inf"),
    "time-nan": _plain_with(3, 0, b"nan"),
    "time-1e400": _plain_with(3, 0, b"1e400"),
    "time-empty": _plain_with(3, 0, b""),
    "header-only": b"time,jawOpen\n",
    "short-row": b"time,jawOpen,eyeBlinkLeft\n0.0,0.1,0.2\n0.1,0.1\n",
    "header-not-utf8": b"time,jaw\xffOpen\n0.0,0.1\n",
    "cell-not-utf8": _plain_with(3, 4, b"0.\xff"),
    "cell-word": _plain_with(3, 4, b"half"),
    "cell-two-dots": _plain_with(3, 4, b"0.1.2"),
}


@pytest.mark.parametrize("how", ["info", "stream", "convert"])
@pytest.mark.parametrize("name", list(PLAIN_REFUSED))
def test_plain_malformed_is_refused_by_every_reader(tmp_path, name, how):
    src = tmp_path / "plain.csv"
    src.write_bytes(PLAIN_REFUSED[name])
    refused(_run_reader(how, src, tmp_path))
    no_temp_files(tmp_path)


TIMES = {
    "1e300-apart": [0.0, 1e300, 2e300, 3e300],
    "span-overflows": [-1e308, 1e308, 1.5e308, 1.7e308],
    "subnormal-steps": [0.0, 5e-324, 1e-323, 1.5e-323],
    "backwards": [3.0, 2.0, 1.0, 0.0],
    "all-equal": [1.0, 1.0, 1.0, 1.0],
}
TIMES_FAILS = {
    (
        "span-overflows",
        "one-euro",
    ): "wrong answer: numpy RuntimeWarning (overflow, filters/base.py)",
    ("span-overflows", "lstm"): "wrong answer: numpy RuntimeWarning (overflow, filters/base.py)",
    ("subnormal-steps", "lstm"): "internal error: ZeroDivisionError on subnormal time steps",
}


def _times_cases():
    for name in TIMES:
        for method in ("one-euro", "lstm"):
            reason = TIMES_FAILS.get((name, method))
            yield pytest.param(
                TIMES[name], method, id=f"{name}-{method}", marks=[fail(reason)] if reason else []
            )


@pytest.mark.parametrize(("times", "method"), list(_times_cases()))
def test_plain_absurd_times_never_erase_data(tmp_path, times, method):
    x = curves(len(times), 3)
    src = tmp_path / "plain.csv"
    src.write_bytes(plain_text(names=["jawOpen", "eyeBlinkLeft", "custom"], values=x,
                               times=np.array(times)))  # fmt: skip
    out = tmp_path / "out.csv"
    if ok_or_refused(fc("clean", src, "-o", out, "--method", method)):
        finite_where_input_was(x, read_plain(out)[1][:, 1:])
