"""Fuzz targets beyond files and packets: the tuning page's messages and folders of pairs.

``page``: one text message from the browser, answered in-process by the server's own
``ui.server.receive`` over an offline session on a short take. The property: every answer
is strict JSON (no NaN/Infinity) that UTF-8 can carry, an error is one line and never an
internal error, and a refused message leaves the session's state (tuning and view) as it
was. Paths in a message are kept inside the fuzz folder (``_sandboxed``), so the run
never writes elsewhere.

``pairs``: a folder of pairs (``NAME.tracked.csv``, ``NAME.truth.csv``, ``NAME.json``,
maybe a subfolder) packed in one byte string (``pack``): ``paired.load`` then
``paired.usable`` return pairs, every value kept finite within MAX_ABS or NaN, or
raise a one-line FacecleanError. Inputs are drawn from seeded valid ones by structured
edits (keys, types, huge numbers, NaN tokens, lone surrogates, deep nesting, bad cells,
shifted times, missing files) and the byte-level edits of ``fuzz_inputs.mutated``.
"""

from __future__ import annotations

import json
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from faceclean.errors import FacecleanError

TARGETS = ("page", "pairs")
# Values a field may be replaced by: wrong types, extremes, non-finite, long or odd text.
ODD: tuple[Any, ...] = (
    None, True, 0, -1, 2**64, 10**400, 1e308, -1e308, 1.5, float("nan"), float("inf"), "",
    " ", "x" * 5000, "\ud800", "a\x00b", "one-euro", "kalman", [], {}, [[[[[]]]]], ["x"] * 300,
)  # fmt: skip
ITEMS = (
    "min_cutoff=1", "beta=0.5", "r=1e300", "q=0.5", "min_cutoff=nan", "beta=inf", "beta=-1e309",
    "jawOpen.gain=1e400", "eyes.clamp=0.9,0.1", "nobody.beta=1", "x" * 2000, "=", "\ud800=1",
)  # fmt: skip
KEYS = ("type", "seq", "words", "items", "tracker", "what", "path", "t0", "t1", "seconds")
KEYS += ("start", "__proto__", "\ud800", "")
MESSAGES: tuple[dict[str, Any], ...] = (
    {"type": "set", "seq": 1, "words": "one-euro", "items": ["min_cutoff=1"]},
    {"type": "set", "seq": 2, "words": "kalman", "items": ["q=0.5"], "tracker": None},
    {"type": "view", "seq": 3, "t0": 0.0, "t1": 0.4},
    {"type": "calibrate", "seq": 4, "seconds": 0.2, "start": 0.0},
    {"type": "uncalibrate", "seq": 5},
    {"type": "save", "seq": 6, "what": "preset", "path": "p.json"},
    {"type": "save", "seq": 7, "what": "levels", "path": "l.json"},
    {"type": "load", "seq": 8, "what": "preset", "path": "p.json"},
    {"type": "load", "seq": 9, "what": "levels", "path": "l.json"},
    {"type": "load", "seq": 10, "what": "levels", "path": "/proc/self/mem"},
    {"type": "export", "seq": 11, "path": "out.csv"},
)
SPECIAL = ("/proc/self/mem", "/proc/self/status", "/dev/zero", "/dev/null")  # read, never written


# -- the page ---------------------------------------------------------------------------------


def page_message(rng: np.random.Generator) -> bytes:
    """A valid message with structured edits, then maybe byte-level ones (or deep nesting)."""
    from faceclean.evaluation.fuzz_inputs import mutated

    m = dict(MESSAGES[int(rng.integers(len(MESSAGES)))])
    for _ in range(int(rng.integers(0, 4))):
        kind, key = int(rng.integers(5)), KEYS[int(rng.integers(len(KEYS)))]
        if kind == 0:  # a field of the wrong kind or size
            m[key] = ODD[int(rng.integers(len(ODD)))]
        elif kind == 1:
            m.pop(key, None)
        elif kind == 2:  # items the CLI refuses (or takes)
            m["items"] = [ITEMS[int(i)] for i in rng.integers(len(ITEMS), size=rng.integers(4))]
        elif kind == 3:  # another message's type
            m["type"] = MESSAGES[int(rng.integers(len(MESSAGES)))]["type"]
        else:  # a huge or tiny number
            m[key] = float(rng.choice([-1, 1]) * 10.0 ** rng.integers(-320, 309))
    text = json.dumps(m, ensure_ascii=bool(rng.integers(2)))  # NaN/Infinity tokens too
    data = text.encode("utf-8", "surrogatepass")
    u = rng.random()
    if u < 0.1:
        n = int(rng.integers(100, 100_000))
        return b'{"type": "set", "items": ' + b"[" * n + b"]" * n + b"}"
    if u < 0.4:
        return mutated(rng, (data,))
    return data


class Page:
    """The ``page`` check: ``__call__(data)`` answers one message; True when accepted."""

    def __init__(self, folder: Path) -> None:
        from faceclean import io
        from faceclean.evaluation.fuzz_inputs import sample_animation
        from faceclean.ui.offline import Offline
        from faceclean.ui.server import Client
        from faceclean.ui.session import Base
        from faceclean.ui.tuning import Tuning

        class Quiet(Offline):  # answers in this thread: no worker cleaning the whole take
            use = Base.use

        class Connection:
            def send(inner, data: str | bytes) -> None:
                if isinstance(data, str):
                    self.sent.append(data)

        self.folder = folder
        take = folder / "take.csv"
        io.save(sample_animation(), take)
        self.session = Quiet(str(take), Tuning("one-euro"))
        self.sent: list[str] = []
        self.client = Client(Connection())
        self.session.attach(self.client)

    def state(self) -> str:
        from faceclean import strict_json

        with self.session.lock:
            return strict_json.dumps(self.session.tuning.describe()) + repr(self.session.window)

    def __call__(self, data: bytes) -> bool:
        from faceclean.ui.server import receive

        raw = _sandboxed(data.decode("utf-8", "replace"), self.folder)
        if raw is None:
            return False
        before, kind = self.state(), _kind(raw)
        self.sent.clear()
        receive(self.session, self.client, raw)
        refused = False
        for text in self.sent:
            answer = json.loads(text, parse_constant=_no_constant)  # strict JSON
            text.encode("utf-8")  # a text frame carries it
            assert isinstance(answer, dict) and isinstance(answer.get("type"), str)
            if answer["type"] == "error":
                said = answer.get("message")
                assert isinstance(said, str) and said.startswith("faceclean: "), said
                assert "\n" not in said and "internal error" not in said, said
                refused = refused or answer.get("for") in (None, kind)
        if refused:
            assert self.state() == before, "a refused message changed the state"
        return not refused


def _no_constant(token: str) -> Any:
    raise AssertionError(f"{token} in an answer: not strict JSON")


def _kind(raw: str) -> Any:
    try:
        m = json.loads(raw)
    except (ValueError, RecursionError):
        return None
    return m.get("type") if isinstance(m, dict) else None


def _sandboxed(raw: str, folder: Path) -> str | None:
    """``raw`` with its ``path`` (a text) moved into ``folder``, the file's name kept (NUL,
    surrogates, length and all); a few special files stay for ``load``. None: a message
    with a path that cannot be rewritten (skipped)."""
    try:
        m = json.loads(raw)
    except (ValueError, RecursionError):
        return raw
    if not isinstance(m, dict) or not isinstance(m.get("path"), str):
        return raw
    path = m["path"]
    if not (path in SPECIAL and m.get("type") == "load" or path == "/dev/null"):
        m["path"] = str(folder / ("f" + path.replace("/", "_").replace("\\", "_")))
    try:
        return json.dumps(m)
    except (ValueError, RecursionError):
        return None


# -- folders of pairs ---------------------------------------------------------------------------


def pack(files: dict[str, bytes]) -> bytes:
    """Files as one byte string: per file, a name length (1 byte), the name, a content length
    (4 bytes, little-endian), the content."""
    out = b""
    for name, content in files.items():
        raw = name.encode()[:255]
        out += bytes([len(raw)]) + raw + len(content).to_bytes(4, "little") + content
    return out


def unpack(data: bytes) -> dict[str, bytes]:
    """``pack``'s files back, as far as the bytes hold them; names kept to ``[\\w.-]+`` in
    at most one subfolder (never ``..``)."""
    files, at = {}, 0
    while at < len(data):
        n = data[at]
        name = data[at + 1 : at + 1 + n].decode("utf-8", "replace")
        size = int.from_bytes(data[at + 1 + n : at + 5 + n], "little")
        files[_safe(name)] = data[at + 5 + n : at + 5 + n + size]
        at += 5 + n + size
    return files


def _safe(name: str) -> str:
    parts = [re.sub(r"[^\w.-]", "_", p).lstrip(".") or "_" for p in name.split("/")[-2:]]
    return "/".join(parts)


def pairs_seed() -> dict[str, bytes]:
    """A real pair (``faceclean pairs``' own file names and metadata), and its ROM clip."""
    from faceclean import io
    from faceclean.animation import Animation
    from faceclean.evaluation.fuzz_inputs import sample_animation
    from faceclean.synthetic.engine import FORMAT

    truth = sample_animation()
    rng = np.random.default_rng(0)
    noisy = np.clip(truth.values + 0.05 * rng.standard_normal(truth.values.shape), 0, 1)
    tracked = Animation(truth.times, noisy, truth.names)
    files = {}
    with tempfile.TemporaryDirectory() as d:
        for name, anim in (("a.tracked.csv", tracked), ("a.truth.csv", truth)):
            io.save(anim, Path(d) / name, "csv")
            files[name] = (Path(d) / name).read_bytes()
    files["a.rom.tracked.csv"], files["a.rom.truth.csv"] = (
        files["a.tracked.csv"],
        files["a.truth.csv"],
    )
    job = {"group": "g", "setting": "s", "family": "painted"}
    files["a.json"] = json.dumps({"format": FORMAT, "job": job}).encode()
    return files


BAD_CELLS = (b"inf", b"-inf", b"nan", b"1e308", b"-1e309", b"abc", b"", b"0x10", b"1,2", b'"')
NAMES = ("a.tracked.csv", "a.truth.csv", "a.json", "a.raw.csv", "a.clean.csv", "a.truth.json")
NAMES += ("b.tracked.csv", "sub/a.tracked.csv", "sub/a.truth.csv", "a.tracked.npz")


def pairs_folder(rng: np.random.Generator) -> bytes:
    """The seed folder with 1 to 4 edits: a cell made bad, times shifted, a file removed,
    renamed, copied over another, or given byte-level edits (``fuzz_inputs.mutated``)."""
    from faceclean.evaluation.fuzz_inputs import mutated

    files = pairs_seed()
    for _ in range(int(rng.integers(1, 5))):
        names = sorted(files)
        if not names:
            break
        name, kind = names[int(rng.integers(len(names)))], int(rng.integers(6))
        if kind == 0:  # a number cell made bad
            cells = list(re.finditer(rb"-?\d+\.?\d*(e-?\d+)?", files[name]))
            if cells:
                c = cells[int(rng.integers(len(cells)))]
                bad = BAD_CELLS[int(rng.integers(len(BAD_CELLS)))]
                files[name] = files[name][: c.start()] + bad + files[name][c.end() :]
        elif kind == 1:  # times moved (the first column): mismatched instants
            lines = files[name].split(b"\n")
            k = int(rng.integers(1, max(len(lines), 2)))
            if k < len(lines) and b"," in lines[k]:
                lines[k] = (
                    b"%r" % float(rng.normal() * 10.0 ** rng.integers(-4, 4))
                    + lines[k][lines[k].index(b",") :]
                )
            files[name] = b"\n".join(lines)
        elif kind == 2:  # a missing file
            del files[name]
        elif kind == 3:  # renamed
            files[NAMES[int(rng.integers(len(NAMES)))]] = files.pop(name)
        elif kind == 4:  # another file's content (truth as tracked, JSON as CSV)
            files[name] = files[names[int(rng.integers(len(names)))]]
        else:
            files[name] = mutated(rng, (files[name],))
    return pack(files)


class Pairs:
    """The ``pairs`` check: ``__call__(data)`` loads the packed folder; True when pairs."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder / "pairs"

    def __call__(self, data: bytes) -> bool:
        from faceclean.datasets import paired
        from faceclean.filters.base import MAX_ABS

        shutil.rmtree(self.folder, ignore_errors=True)
        self.folder.mkdir(parents=True)
        for name, content in unpack(data).items():
            path = self.folder / name
            path.parent.mkdir(exist_ok=True)
            if not path.is_dir():
                path.write_bytes(content)
        try:
            kept, skipped, notes = paired.usable(paired.load(self.folder))
        except FacecleanError as e:
            assert "\n" not in str(e), f"multi-line message {str(e)!r}"
            return False
        for line in (*skipped, *notes):
            assert isinstance(line, str) and "\n" not in line
        for p in kept:
            for anim in (p.tracked, p.truth, p.rom, p.rom_truth):
                if anim is not None:
                    v = anim.values
                    assert (np.isnan(v) | (np.abs(v) <= MAX_ABS)).all(), "a bad value kept"
        return bool(kept)


def seeds(target: str) -> tuple[bytes, ...]:
    """Valid inputs (each accepted as it is)."""
    if target == "page":
        return tuple(json.dumps(m).encode() for m in MESSAGES if m["type"] != "load")
    return (pack(pairs_seed()),)


def draw(rng: np.random.Generator, target: str) -> bytes:
    """One input: a seed with structured and byte-level edits."""
    return page_message(rng) if target == "page" else pairs_folder(rng)


def checker(target: str, folder: Path) -> Page | Pairs:
    return Page(folder) if target == "page" else Pairs(folder)
