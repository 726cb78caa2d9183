"""Fuzzing: every file reader and every relay decoder, fed arbitrary and mutated real bytes.

The property (docs/ROBUSTNESS.md): a reader returns an Animation that holds the
invariants (at least one frame, finite times, (N, M) float64 values, M text names) or
raises FacecleanError; a decoder returns a Frame (or None: nothing complete yet) or
raises Malformed, the relay's counted rejection. Anything else is a bug. A readable
file must also write back in its own format without any other error, and a Live Link
file must come back byte for byte.

Inputs come from a seeded numpy generator (``draw``): arbitrary bytes, and real files
or packets (``seeds``) mutated by a few byte-level edits (flips, cuts, repeats, splices
of tokens that parsers care about); a failing input is shrunk by deleting spans. No
hypothesis here (a dev dependency): ``tests/evaluation/test_fuzz.py`` drives the same
``Checker`` with hypothesis in ``make test``; ``faceclean fuzz`` runs this fuzzer long.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.evaluation.fuzz_inputs import TOKENS, mutated, sample_animation  # noqa: F401

READERS = {"livelink": ".csv", "csv": ".csv", "json": ".json", "npz": ".npz", "glb": ".glb"}
READERS.update(gltf=".gltf", mediapipe=".csv")
DECODERS = ("vmc", "livelink-udp", "ifacialmocap")
SURFACES = ("page", "pairs")  # evaluation/fuzz_surfaces.py: the page's messages, pair folders
TARGETS: tuple[str, ...] = (*READERS, *DECODERS, *SURFACES)
MAX_BYTES = 4096  # arbitrary inputs up to this size


@dataclass
class Report:
    """One fuzz run: how many inputs each outcome had; a failure, if one was found."""

    target: str
    tried: int = 0
    accepted: int = 0  # readable files / decoded frames
    refused: int = 0  # FacecleanError / Malformed
    seconds: float = 0.0
    failure: str | None = None  # one line: the exception and the input that raised it
    failing_input: bytes | None = None
    outcomes: dict[str, int] = field(default_factory=dict)


class Checker:
    """Runs one target on one input; raises AssertionError (or anything) on a bug."""

    def __init__(self, target: str, folder: str | os.PathLike) -> None:
        if target not in TARGETS:
            raise FacecleanError(f"unknown fuzz target {target!r} (known: {', '.join(TARGETS)})")
        self.target = target
        self.folder = Path(folder)
        self._check: Callable[[bytes], bool]
        if target in SURFACES:
            from faceclean.evaluation import fuzz_surfaces

            self._check = fuzz_surfaces.checker(target, self.folder)
        else:
            self._check = self._reader if target in READERS else _DECODERS[target]

    def __call__(self, data: bytes) -> bool:
        """True: accepted; False: refused as the policy says. Raises on a bug."""
        return self._check(data)

    def _reader(self, data: bytes) -> bool:
        from faceclean import io

        fmt = "gltf" if self.target in ("glb", "gltf") else self.target
        src = self.folder / f"in{READERS[self.target]}"
        src.write_bytes(data)
        try:
            anim = io.load(src, fmt)
        except FacecleanError as e:
            assert "\n" not in str(e), f"multi-line message {str(e)!r}"
            return False
        check_animation(anim)
        assert src.read_bytes() == data, "the reader modified its input"
        out = self.folder / f"out{READERS[self.target]}"
        try:
            io.save(anim, out, fmt)
        except FacecleanError:
            return True  # a readable file that cannot go back (e.g. inf in JSON): refused
        if fmt == "livelink":
            assert out.read_bytes() == data, "Live Link write-back changed bytes"
        return True


def check_animation(anim: Any) -> None:
    """The invariants every reader promises (raises AssertionError)."""
    assert isinstance(anim, Animation)
    n, m = anim.n_frames, anim.n_channels
    assert n >= 1 and m >= 1
    assert anim.times.dtype == np.float64 and anim.times.shape == (n,)
    assert np.isfinite(anim.times).all()
    assert anim.values.dtype == np.float64 and anim.values.shape == (n, m)
    assert all(isinstance(name, str) for name in anim.names)
    assert isinstance(anim.meta.get("format"), str)


def _check_frame(frame: Any) -> bool:
    from faceclean.relay.frame import Frame

    if frame is None:
        return True
    assert isinstance(frame, Frame)
    assert all(isinstance(n, str) for n in frame.names)
    assert isinstance(frame.values, np.ndarray) and frame.values.shape == (len(frame.names),)
    assert frame.values.dtype == np.float64
    assert frame.t is None or (isinstance(frame.t, float) and np.isfinite(frame.t))
    assert frame.pose is None or frame.pose.shape == (9,)
    assert all(isinstance(p, bytes) for p in frame.passthrough)
    return True


def _decode_with(decode: Callable[[bytes], Any]) -> Callable[[bytes], bool]:
    def check(data: bytes) -> bool:
        from faceclean.relay.frame import Malformed

        try:
            frame = decode(data)
        except Malformed as e:
            assert "\n" not in str(e)
            return False
        return _check_frame(frame)

    return check


def _vmc(data: bytes) -> bool:
    """A fresh decoder fed the input as three datagrams (loose messages across them)."""
    from faceclean.relay import vmc
    from faceclean.relay.frame import Malformed

    decoder = vmc.Decoder()
    cut1, cut2 = len(data) // 3, 2 * len(data) // 3
    ok = False
    for part in (data[:cut1], data[cut1:cut2], data[cut2:], data):
        try:
            ok = _check_frame(decoder.feed(part)) or ok
        except Malformed as e:
            assert "\n" not in str(e)
    return ok


def _livelink_udp(data: bytes) -> bool:
    from faceclean.relay import livelink

    return _decode_with(livelink.decode)(data)


def _ifacialmocap(data: bytes) -> bool:
    from faceclean.relay import ifacialmocap

    return _decode_with(ifacialmocap.decode)(data)


_DECODERS: dict[str, Callable[[bytes], bool]] = {
    "vmc": _vmc,
    "livelink-udp": _livelink_udp,
    "ifacialmocap": _ifacialmocap,
}


# -- seeds: real inputs to mutate ----------------------------------------------------------


@cache
def seeds(target: str) -> tuple[bytes, ...]:
    """Well-formed inputs of a target: real data where the shared folder has it."""
    if target in SURFACES:
        from faceclean.evaluation import fuzz_surfaces

        return fuzz_surfaces.seeds(target)
    if target in ("livelink", "csv", "json", "npz"):
        return tuple(_file_seeds(target))
    if target in ("glb", "gltf"):
        return (_gltf_seed(target == "glb"),)
    if target == "mediapipe":
        return tuple(_mediapipe_seeds())
    return tuple(_packet_seeds(target))


def _file_seeds(fmt: str) -> list[bytes]:
    from faceclean import io

    anim = sample_animation()
    out = []
    with tempfile.TemporaryDirectory() as d:
        for i, a in enumerate(
            (anim, Animation(anim.times[:3], anim.values[:3, :4], anim.names[:4]))
        ):
            p = Path(d) / f"s{i}{READERS[fmt]}"
            io.save(a, p, fmt)
            out.append(p.read_bytes())
    return out


def _mediapipe_seeds() -> list[bytes]:
    """As scripts around the Face Landmarker write them: ``frame``, ``timestamp_ms`` (ints)
    and every category (``_neutral`` first), one lost face; and seconds in ``timestamp``."""
    from faceclean.channels import MEDIAPIPE

    anim = sample_animation()
    scores = np.clip(anim.values[:, : len(MEDIAPIPE)], 0, 1)  # (N, 52)
    rows = ["frame,timestamp_ms," + ",".join(MEDIAPIPE)]
    for k, (t, v) in enumerate(zip(anim.times, scores, strict=True)):
        cells = [""] * len(v) if np.isnan(v).all() else [f"{x:.6f}" for x in v]
        rows.append(f"{k},{round(t * 1000)}," + ",".join(cells))
    short = ["timestamp,_neutral,jawOpen"] + [f"{k / 30:.4f},0.9,0.{k}" for k in range(4)]
    return [("\n".join(r) + "\n").encode() for r in (rows, short)]


def _gltf_seed(glb: bool) -> bytes:
    """A tiny glTF: a triangle with two morph targets, five weight keyframes."""
    import base64

    import pygltflib as g

    pos = np.eye(3, dtype="<f4")
    times = np.arange(5, dtype="<f4") / 30
    weights = np.linspace(0, 1, 10, dtype="<f4")
    parts = [pos.tobytes(), (pos * 0.1).tobytes(), (pos * 0.2).tobytes()]
    parts += [times.tobytes(), weights.tobytes()]
    views, blob = [], b""
    for data in parts:
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
        blob += data
    vec = {"componentType": g.FLOAT, "count": 3, "type": "VEC3", "min": [0.0] * 3}
    vec["max"] = [1.0] * 3
    accessors = [g.Accessor(bufferView=i, **vec) for i in range(3)]
    accessors.append(g.Accessor(bufferView=3, componentType=g.FLOAT, count=5, type="SCALAR"))
    accessors.append(g.Accessor(bufferView=4, componentType=g.FLOAT, count=10, type="SCALAR"))
    prim = g.Primitive(
        attributes=g.Attributes(POSITION=0), targets=[{"POSITION": 1}, {"POSITION": 2}]
    )
    gltf = g.GLTF2(
        scene=0,
        scenes=[g.Scene(nodes=[0])],
        nodes=[g.Node(mesh=0)],
        meshes=[g.Mesh(primitives=[prim], extras={"targetNames": ["jawOpen", "eyeBlinkLeft"]})],
        accessors=accessors,
        bufferViews=views,
        buffers=[g.Buffer(byteLength=len(blob))],
        animations=[
            g.Animation(
                samplers=[g.AnimationSampler(input=3, output=4)],
                channels=[
                    g.AnimationChannel(
                        sampler=0, target=g.AnimationChannelTarget(node=0, path="weights")
                    )
                ],
            )
        ],
    )
    if glb:
        gltf.set_binary_blob(blob)
        return b"".join(gltf.save_to_bytes())
    gltf.buffers[0].uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    return gltf.gltf_to_json().encode()


def _packet_seeds(target: str) -> list[bytes]:
    from faceclean.relay import livelink, vmc
    from faceclean.relay.frame import Frame
    from faceclean.settings import data_dir

    rng = np.random.default_rng(0)
    frame = Frame(ARKIT52, rng.random(52), 12.5, np.zeros(9))
    if target == "livelink-udp":
        rec = data_dir() / "raw_streams" / "llv_dao.gesichter" if data_dir() else None
        if rec is not None and rec.is_file():
            return livelink.read_recording(rec)[:8]
        return [livelink.Encoder().encode(frame)]
    if target == "vmc":
        return [vmc.Encoder(stamp=True).encode(frame), vmc.Encoder(names="lr").encode(frame)]
    text = "|".join(f"{n}-{int(v * 100)}" for n, v in zip(ARKIT52, frame.values, strict=True))
    return [(text + "|=head#1.0,2.0,3.0,0.1,0.2,0.3|").encode(), text.replace("-", "&").encode()]


# -- the mutation fuzzer and the long run --------------------------------------------------


def draw(rng: np.random.Generator, target: str) -> bytes:
    """One input for ``target``: arbitrary bytes (a quarter), a seed as is (an eighth),
    else a mutated seed; the page's messages and pair folders get their own edits."""
    if target in SURFACES:
        from faceclean.evaluation import fuzz_surfaces

        return fuzz_surfaces.draw(rng, target)
    pool = seeds(target)
    u = rng.random()
    if u < 0.25:
        return rng.bytes(int(rng.integers(MAX_BYTES + 1)))
    if u < 0.375:
        return pool[int(rng.integers(len(pool)))]
    return mutated(rng, pool)


def shrink(fails: Callable[[bytes], bool], data: bytes, budget: int = 400) -> bytes:
    """A shorter input that still ``fails``: spans deleted, halves first, then smaller
    (at most ``budget`` tries)."""
    span = max(len(data) // 2, 1)
    while span >= 1 and budget > 0:
        at = 0
        while at < len(data) and budget > 0:
            budget -= 1
            shorter = data[:at] + data[at + span :]
            if fails(shorter):
                data = shorter
            else:
                at += span
        span //= 2
    return data


def run(
    target: str,
    examples: int | None = None,
    seconds: float | None = None,
    batch: int = 2000,
    on_batch: Callable[[Report], None] | None = None,
    seed: int = 0,
) -> Report:
    """Fuzz one target for ``examples`` inputs or ``seconds`` seconds (numpy's generator
    seeded with ``seed``: the same inputs every run), reporting after every ``batch``.
    Stops at the first failure, shrunk."""
    if (examples is None) == (seconds is None):
        raise FacecleanError("give a number of examples or a number of seconds")
    report = Report(target)
    rng = np.random.default_rng([seed, TARGETS.index(target)])
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="faceclean-fuzz-") as folder:
        check = Checker(target, folder)

        def failure(data: bytes) -> BaseException | None:
            try:
                check(data)
            except Exception as e:  # anything but the policy's refusal is a bug
                return e
            return None

        while True:
            if examples is not None and report.tried >= examples:
                break
            if seconds is not None and time.monotonic() - start >= seconds:
                break
            data = draw(rng, target)
            report.tried += 1
            try:
                ok = check(data)
            except Exception as e:
                small = shrink(lambda d: failure(d) is not None, data)
                report.failing_input, report.failure = small, _one_line(failure(small) or e)
                break
            if ok:
                report.accepted += 1
            else:
                report.refused += 1
            if on_batch is not None and report.tried % batch == 0:
                report.seconds = time.monotonic() - start
                on_batch(report)
    report.seconds = time.monotonic() - start
    return report


def _one_line(e: BaseException) -> str:
    """``Type: message (file:line)`` of the innermost frame, on one line."""
    import traceback

    text = " ".join(str(e).split())[:300]
    where = traceback.extract_tb(e.__traceback__)[-1] if e.__traceback__ else None
    at = f" ({Path(where.filename).name}:{where.lineno})" if where else ""
    return (f"{type(e).__name__}: {text}" if text else type(e).__name__) + at


def failing_example(report: Report) -> str:
    """The failing input as a short Python literal (for a bug report or a test)."""
    data = report.failing_input or b""
    return repr(data[:200]) + (f" ... ({len(data)} bytes)" if len(data) > 200 else "")


__all__ = [
    "DECODERS", "READERS", "SURFACES", "TARGETS", "Checker", "Report", "check_animation", "draw",
    "mutated", "run", "seeds", "shrink",
]  # fmt: skip
