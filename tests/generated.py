"""Generated hostile cases (hypothesis): structure-aware inputs for every entry point.

Dev-only: hypothesis is a dev dependency and the library never imports this module.
``tests/test_generated.py`` runs each property briefly in ``make test`` (fixed profile);
``faceclean fuzz --generated`` loads this file from the source checkout and runs the same
properties long. Each property takes one generated case and asserts the policy of
docs/ROBUSTNESS.md: a right answer or a FacecleanError (Malformed for datagrams), never
any other exception, a non-finite output where the input was finite, or a bound broken.
"""

from __future__ import annotations

import contextlib
import json
import struct
import tempfile
from pathlib import Path

import numpy as np
from helpers import gltf_doc
from hypothesis import strategies as st

from faceclean import filters, io, strict_json
from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.relay import bounds, livelink, osc, vmc
from faceclean.relay.frame import Malformed

NAMES = ("jawOpen", "eyeBlinkLeft", "mouthSmileRight")
T = np.arange(30) / 30.0
X = 0.5 + 0.3 * np.sin(2 * np.pi * T[:, None] + np.arange(len(NAMES)))
TAKE = Animation(T, X, NAMES, {"format": "csv"})

# Numbers and texts that parsers care about.
FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, 5e-324, 1e300, 1e308, -1e308, 3.4e38, 1e6, 1e-6]),
)
INTS = st.one_of(
    st.integers(), st.integers(-(10**400), 10**400), st.sampled_from([-1, 0, 2**31, 2**63])
)
I32 = st.integers(-(2**31), 2**31 - 1)
TEXT = st.one_of(
    st.text(max_size=40), st.sampled_from(["", "\ud800", "NaN", "inf", "a,b", "x" * 300])
)
JSON_SCALARS = st.one_of(st.none(), st.booleans(), INTS, FLOATS, TEXT)
JSON_VALUES = st.recursive(
    JSON_SCALARS,
    lambda kids: st.one_of(st.lists(kids, max_size=4), st.dictionaries(TEXT, kids, max_size=4)),
    max_leaves=12,
)


def _value_text(v) -> str:
    try:
        return json.dumps(v)
    except (ValueError, TypeError, OverflowError):
        return str(v)


# -- --set values and presets ---------------------------------------------------------------

SET_TEXT = st.one_of(
    JSON_VALUES.map(_value_text),
    st.text(max_size=30),
    st.integers(1, 20_000).map(lambda n: "[" * n + "]" * n),
    st.integers(300, 5000).map(lambda n: "9" * n),
)
STREAM_METHODS = ("ema", "one-euro", "kalman")
KEYS = {"ema": ("tau",), "one-euro": ("min_cutoff", "beta", "d_cutoff"), "kalman": ("q", "r")}


def check_cleaner(method: str, params: dict) -> None:
    """Build and run a cleaner: it cleans to a finite take, or refuses with one line."""
    try:
        cleaner = filters.make(method, params, names=NAMES)
        out = cleaner.clean(TAKE)
    except FacecleanError:
        return
    assert np.isfinite(out.values).all(), (method, params)


@st.composite
def set_cases(draw):
    method = draw(st.sampled_from(STREAM_METHODS))
    key = draw(st.sampled_from(KEYS[method]))
    return method, {key: strict_json.value(draw(SET_TEXT))}


def check_set(case) -> None:
    check_cleaner(*case)


@st.composite
def preset_docs(draw):
    method = draw(st.one_of(st.sampled_from(STREAM_METHODS), JSON_VALUES))
    keys = KEYS.get(method, ("tau",)) if isinstance(method, str) else ("tau",)
    params = {k: draw(st.one_of(FLOATS, INTS, JSON_VALUES)) for k in keys}
    doc = {"format": "faceclean-preset/1", "method": method, "params": params}
    if draw(st.booleans()):
        doc["groups"] = draw(
            st.dictionaries(st.sampled_from(["eyes", "jaw", "x"]), JSON_VALUES, max_size=2)
        )
    return doc


def check_preset(doc) -> None:
    from faceclean.filters import presets

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "p.json"
        try:
            p.write_text(json.dumps(doc))
        except (ValueError, TypeError, OverflowError):
            return
        try:
            cleaner = presets.build(p, NAMES)
            out = cleaner.clean(TAKE)
        except FacecleanError:
            return
        assert np.isfinite(out.values).all(), doc


# -- files: JSON, NPZ, glTF structure ---------------------------------------------------------


def check_file(path: Path) -> None:
    """A reader returns the invariants or refuses; every writer then writes or refuses."""
    try:
        anim = io.load(path)
    except FacecleanError:
        return
    assert anim.n_frames >= 1 and np.isfinite(anim.times).all()
    assert anim.values.dtype == np.float64 and anim.values.shape == (anim.n_frames, len(anim.names))
    for suffix, fmt in ((".csv", "livelink"), (".csv", "csv"), (".json", None), (".npz", None)):
        with contextlib.suppress(FacecleanError):
            io.save(anim, path.parent / f"out{suffix}", fmt=fmt)


@st.composite
def json_docs(draw):
    n = draw(st.integers(0, 4))
    doc = {
        "format": draw(st.sampled_from(["faceclean-animation/1", "other"])),
        "channels": draw(st.one_of(st.just(list(NAMES[:2])), JSON_VALUES)),
        "times": draw(st.one_of(st.lists(FLOATS, min_size=n, max_size=n), JSON_VALUES)),
        "values": draw(
            st.one_of(
                st.lists(st.lists(FLOATS, min_size=2, max_size=2), min_size=n, max_size=n),
                JSON_VALUES,
            )
        ),
    }
    for key in ("pose", "pose_names", "timecode_start"):
        if draw(st.booleans()):
            doc[key] = draw(JSON_VALUES)
    return doc


def check_json(doc) -> None:
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "a.json"
        p.write_text(json.dumps(doc), encoding="utf-8", errors="surrogatepass")
        check_file(p)


DTYPES = st.sampled_from(["<f8", "<f4", "<i8", "<u1", "?", "<c16", "<U8", "|S8"])


@st.composite
def arrays(draw, shape):
    dtype = np.dtype(draw(DTYPES))
    if dtype.kind in "US":
        pool = [b"jawOpen", b"\xff\xfe", b"x"] if dtype.kind == "S" else ["jawOpen", "\ud800", "x"]
        return np.array(
            [draw(st.sampled_from(pool)) for _ in range(int(np.prod(shape)))], dtype
        ).reshape(shape)
    values = draw(st.lists(FLOATS, min_size=int(np.prod(shape)), max_size=int(np.prod(shape))))
    with np.errstate(all="ignore"):
        a = np.array(values, np.float64)
        return (
            np.nan_to_num(a).astype(dtype).reshape(shape)
            if dtype.kind in "iub"
            else a.astype(dtype).reshape(shape)
        )


@st.composite
def npz_members(draw):
    n, m = draw(st.integers(0, 3)), draw(st.integers(0, 3))
    shapes = st.sampled_from([(n,), (n, m), (m,), (), (n, 1)])
    out = {k: draw(arrays(draw(shapes))) for k in ("times", "values", "names")}
    for k in ("pose", "pose_names", "timecode_start"):
        if draw(st.booleans()):
            out[k] = draw(arrays(draw(shapes)))
    return out


def check_npz(members) -> None:
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "a.npz"
        np.savez(p, **members)
        check_file(p)


def _gltf_doc() -> tuple[dict, bytes]:
    return gltf_doc("buf.bin")


GLTF_FIELDS = [
    ("buffers", 0, "uri"), ("buffers", 0, "byteLength"), ("bufferViews", 0, "byteOffset"),
    ("bufferViews", 1, "byteLength"), ("bufferViews", 1, "byteStride"),
    ("bufferViews", 1, "buffer"),
    ("accessors", 1, "componentType"), ("accessors", 1, "count"), ("accessors", 1, "byteOffset"),
    ("accessors", 1, "bufferView"), ("accessors", 0, "type"), ("nodes", 0, "mesh"),
]  # fmt: skip
URIS = st.sampled_from(["../buf.bin", "/etc/passwd", "%2e%2e/buf.bin", "file:///x", "data:,x",
                        "data:;base64,AAAA", "buf.bin/..", "sub/../buf.bin", ""])  # fmt: skip


@st.composite
def gltf_cases(draw):
    doc, data = _gltf_doc()
    for _ in range(draw(st.integers(1, 3))):
        top, i, key = draw(st.sampled_from(GLTF_FIELDS))
        doc[top][i][key] = draw(URIS if key == "uri" else st.one_of(INTS, JSON_VALUES))
    return doc, data, draw(st.booleans())


def check_gltf(case) -> None:
    doc, data, glb = case
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d) / "scene"
        folder.mkdir()
        (folder / "buf.bin").write_bytes(data)
        (Path(d) / "buf.bin").write_bytes(b"SECRET" * 10)  # outside: must never be read
        text = json.dumps(doc).encode("utf-8", "surrogatepass")
        if glb:
            text += b" " * (-len(text) % 4)
            body = struct.pack("<II", len(text), 0x4E4F534A) + text
            raw = struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body
            p = folder / "a.glb"
        else:
            raw, p = text, folder / "a.gltf"
        p.write_bytes(raw)
        try:
            anim = io.load(p)
        except FacecleanError:
            return
        assert not np.any(anim.values == np.frombuffer(b"SECR", "<f4")[0])
        check_file(p)


# -- datagrams: OSC (VMC) and Live Link ------------------------------------------------------

ADDRESSES = st.sampled_from(
    ["/VMC/Ext/Blend/Val", "/VMC/Ext/Blend/Apply", "/VMC/Ext/T", "/VMC/Ext/OK", "/x"]
)


@st.composite
def osc_args(draw):
    kind = draw(st.sampled_from("sfidTFN"))
    if kind == "s":
        return kind, osc.pad(draw(TEXT).encode("utf-8", "surrogatepass"))
    if kind == "f":
        return kind, _f32(draw(FLOATS))
    if kind == "i":
        return kind, struct.pack(">i", draw(I32))
    if kind == "d":
        return kind, struct.pack(">d", draw(FLOATS))
    return kind, b""


def _f32(v: float) -> bytes:
    with np.errstate(all="ignore"):
        return np.array([v], ">f4").tobytes()


@st.composite
def osc_packets(draw):
    msgs = []
    for _ in range(draw(st.integers(1, 6))):
        args = draw(st.lists(osc_args(), max_size=3))
        tags = "," + "".join(k for k, _ in args)
        msgs.append(
            osc.pad(draw(ADDRESSES).encode())
            + osc.pad(tags.encode())
            + b"".join(b for _, b in args)
        )
    return osc.bundle(msgs) if draw(st.booleans()) else msgs[0]


def check_vmc(packets) -> None:
    d = vmc.Decoder()
    for p in packets:
        try:
            frame = d.feed(p)
        except Malformed:
            continue
        if frame is None or not frame.is_face:
            continue
        assert len(frame.names) <= bounds.MAX_NAMES
        assert frame.t is None or abs(frame.t) <= bounds.MAX_TIME
        with np.errstate(all="raise"):  # nothing on the way out overflows or warns
            vmc.Encoder().encode(frame)
            livelink.Encoder().encode(frame)


@st.composite
def livelink_packets(draw):
    dev = draw(st.binary(max_size=160))
    sub = draw(st.binary(max_size=160))
    count = draw(st.sampled_from([52, 61, 0, 255]))
    head = bytes([draw(st.sampled_from([6, 5]))]) + struct.pack(">i", len(dev)) + dev
    head += struct.pack(">i", len(sub)) + sub
    number, num, den = (
        draw(I32),
        draw(st.one_of(I32, st.just(60))),
        draw(st.one_of(I32, st.just(1))),
    )
    timing = struct.pack(">i", number) + _f32(draw(FLOATS)) + struct.pack(">ii", num, den)
    timing += bytes([count])
    floats = b"".join(_f32(draw(FLOATS)) for _ in range(min(count, 61)))
    return head + timing + floats


def check_livelink(packet) -> None:
    try:
        frame = livelink.decode(packet)
    except Malformed:
        return
    assert frame.t is None or abs(frame.t) <= bounds.MAX_TIME
    assert frame.values.shape == (52,) and not np.any(np.abs(frame.values) > bounds.MAX_VALUE)
    with np.errstate(all="raise"):
        livelink.Encoder().encode(frame)
        vmc.Encoder().encode(frame)


# name -> (strategy, property): what tests/test_generated.py and `faceclean fuzz` run.
CASES = {
    "set": (set_cases(), check_set),
    "preset": (preset_docs(), check_preset),
    "json": (json_docs(), check_json),
    "npz": (npz_members(), check_npz),
    "gltf": (gltf_cases(), check_gltf),
    "osc": (st.lists(osc_packets(), min_size=1, max_size=4), check_vmc),
    "livelink": (livelink_packets(), check_livelink),
}
