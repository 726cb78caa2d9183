"""What every fuzz target mutates: the tokens parsers treat specially, the byte-level edits
of a seed (``mutated``), and a short sample take (``sample_animation``). fuzz.py (readers,
decoders) and fuzz_surfaces.py (the page's messages, pair folders) both draw on it."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from faceclean.animation import Animation

# Byte strings parsers treat specially, spliced into real inputs.
TOKENS = (
    b",", b"\n", b"\r\n", b"\r", b"\x00", b"nan", b"inf", b"-1e309", b"1e308", b"-0", b"",
    b"null", b"[", b"]", b"{", b'"', b"\xff\xfe", b"\xef\xbb\xbf", b":", b"|", b"-", b"&",
    b"#bundle\x00", b"/VMC/Ext/Blend/Val\x00\x00", b",sf\x00", b"\x7f\xff\xff\xff",
    b"\xff\xff\xff\xff", b"\x80\x00\x00\x00", b"PK\x03\x04", b"glTF", b"99999999999",
)  # fmt: skip


EDITS = 6  # at most this many byte-level edits of a seed per input


def mutated(rng: np.random.Generator, pool: tuple[bytes, ...]) -> bytes:
    """A seed from ``pool`` with 1 to EDITS byte-level edits: a byte flipped, the tail cut,
    a span deleted, a token (TOKENS) spliced in, a span repeated, random bytes inserted."""
    data = bytearray(pool[int(rng.integers(len(pool)))])
    for _ in range(int(rng.integers(1, EDITS + 1))):
        at = int(rng.integers(len(data) + 1))
        kind = int(rng.integers(6))
        if kind == 0 and at < len(data):  # flip a byte
            data[at] = int(rng.integers(256))
        elif kind == 1:  # cut the tail
            del data[at:]
        elif kind == 2:  # delete a span
            del data[at : at + int(rng.integers(1, 65))]
        elif kind == 3:  # splice a token
            data[at:at] = TOKENS[int(rng.integers(len(TOKENS)))]
        elif kind == 4:  # repeat a span
            data[at:at] = data[at : at + int(rng.integers(1, 257))]
        elif kind == 5:  # random bytes
            data[at:at] = rng.bytes(int(rng.integers(1, 17)))
    return bytes(data)


def sample_animation() -> Animation:
    """A short real take (30 rows, tracking loss included) or a synthetic one."""
    from faceclean import io
    from faceclean.settings import takes_dir

    take = takes_dir() / "alexdjulin" / "apfel.csv" if takes_dir() else None
    if take is not None and take.is_file():
        with open(take, "rb") as f:
            head = b"".join(f.readline() for _ in range(31))
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "take.csv"
            p.write_bytes(head)
            return io.load(p)
    t = np.arange(30) / 60.0
    v = 0.5 + 0.4 * np.sin(t[:, None] * np.arange(1, 53))
    v[10] = np.nan
    return Animation.from_arkit(t, v)
