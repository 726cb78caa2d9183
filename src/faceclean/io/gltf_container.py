"""The glTF 2.0 container, read and written once: every glTF reader and writer uses it.

- :func:`parse`: a ``.gltf`` or ``.glb`` file -> its JSON, pygltflib model and buffers,
  read through :mod:`faceclean.io.source` (a regular file, bounded); buffer URIs must be
  relative paths that stay in the file's folder, ``data:`` URIs base64 and bounded.
- :func:`accessor`: the one accessor reader, (count, width) values, dense or sparse, every
  index, offset and stride checked against its buffer (a hostile file: one line).
- :func:`glb`: the one GLB writer (JSON chunk space-padded, BIN chunk zero-padded to 4
  bytes); :func:`data_uri` embeds a buffer in a ``.gltf``.
"""

from __future__ import annotations

import base64
import json
import struct
import urllib.parse
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pygltflib

from faceclean import strict_json
from faceclean.errors import FacecleanError
from faceclean.io import source as bounded

_JSON, _BIN = 0x4E4F534A, 0x004E4942  # GLB chunk types
# componentType -> (little-endian dtype, divisor of a normalised integer, else None)
COMPONENTS: dict[int, tuple[str, float | None]] = {
    pygltflib.FLOAT: ("<f4", None),
    pygltflib.BYTE: ("<i1", 127.0),
    pygltflib.UNSIGNED_BYTE: ("<u1", 255.0),
    pygltflib.SHORT: ("<i2", 32767.0),
    pygltflib.UNSIGNED_SHORT: ("<u2", 65535.0),
    pygltflib.UNSIGNED_INT: ("<u4", None),  # indices only: never normalised
}
SPARSE_INDICES = (pygltflib.UNSIGNED_BYTE, pygltflib.UNSIGNED_SHORT, pygltflib.UNSIGNED_INT)
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}  # accessor type -> components


def parse(p: Path) -> tuple[bytes, dict, pygltflib.GLTF2, int | None, tuple[bytes, ...]]:
    """A .gltf or .glb file -> (raw bytes, JSON, model, BIN chunk offset, buffers)."""
    raw = bounded.read_bytes(p)
    glb = raw.startswith(b"glTF")
    text, bin_offset, bin_chunk = _split_glb(raw, p.name) if glb else (raw, None, None)
    try:
        doc = strict_json.loads(text, f"{p.name}: not a glTF file", numbers=False)
        if not isinstance(doc, dict):
            raise ValueError("the JSON is not an object")
        with warnings.catch_warnings():  # dataclasses_json warns on absent optional fields
            warnings.simplefilter("ignore")
            model = pygltflib.GLTF2.from_dict(doc)
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise FacecleanError(f"{p.name}: not a glTF file ({e})") from None
    buffers = tuple(_buffer(b, bin_chunk, p) for b in model.buffers or [])
    return raw, doc, model, bin_offset, buffers


def _split_glb(raw: bytes, name: str) -> tuple[bytes, int | None, bytes | None]:
    """GLB -> (JSON chunk, file offset of the BIN data, BIN data)."""
    if len(raw) < 20:
        raise FacecleanError(f"{name}: truncated GLB")
    _, version, length = struct.unpack_from("<4sII", raw, 0)
    if version != 2:
        raise FacecleanError(f"{name}: GLB version {version}, only 2 is supported")
    pos, text, bin_offset, bin_data = 12, None, None, None
    while pos + 8 <= min(length, len(raw)):
        size, kind = struct.unpack_from("<II", raw, pos)
        if kind == _JSON and text is None:
            text = raw[pos + 8 : pos + 8 + size]
        elif kind == _BIN and bin_offset is None:
            bin_offset, bin_data = pos + 8, raw[pos + 8 : pos + 8 + size]
        pos += 8 + size
    if text is None:
        raise FacecleanError(f"{name}: GLB without a JSON chunk")
    return text, bin_offset, bin_data


def _buffer(buffer: pygltflib.Buffer, bin_chunk: bytes | None, path: Path) -> bytes:
    uri = buffer.uri
    if uri is None:
        if bin_chunk is None:
            raise FacecleanError(f"{path.name}: a buffer without URI and no GLB BIN chunk")
        return bin_chunk
    if not isinstance(uri, str):
        raise FacecleanError(f"{path.name}: a buffer URI is not text")
    if uri.startswith("data:"):  # base64: 4 characters per 3 bytes
        if len(uri) > bounded.MAX_FILE // 3 * 4 + 256:
            raise FacecleanError(
                f"{path.name}: a data: URI over the {bounded.size_text(bounded.MAX_FILE)} limit"
            )
        head, comma, body = uri.partition(",")
        if not comma or not head.endswith(";base64"):
            raise FacecleanError(f"{path.name}: a data: URI that is not base64")
        try:
            return base64.b64decode(body, validate=True)
        except ValueError:
            raise FacecleanError(f"{path.name}: a data: URI that is not base64") from None
    name = urllib.parse.unquote(uri)
    if ":" in uri.split("/", 1)[0] or Path(name).is_absolute() or "\\" in name:
        raise FacecleanError(f"{path.name}: buffer URI {uri[:60]!r} is not a relative file path")
    folder = path.parent.resolve()
    target = (folder / name).resolve()  # symlinks followed: they must stay inside too
    if not target.is_relative_to(folder):
        raise FacecleanError(f"{path.name}: buffer URI {uri[:60]!r} leaves the file's folder")
    if not target.exists():
        raise FacecleanError(f"{path.name}: buffer file {uri[:60]!r} not found beside it")
    return bounded.read_bytes(target, what="buffer file")


def count(v: object, what: str) -> int:
    """A glTF index, count, offset or stride: a non-negative integer, else one line."""
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise FacecleanError(f"{what} {v!r} is not a non-negative integer")
    return v


def accessor(
    model: pygltflib.GLTF2, buffers: tuple[bytes, ...], i: object, normalized: bool | None = None
) -> np.ndarray:
    """(count, width) values of accessor ``i``, dense or sparse: floats as float64,
    normalised integers as float64 in [-1, 1] / [0, 1], other integers as stored.

    ``normalized`` overrides the accessor's own flag (weights are always normalised).
    """
    acc = model.accessors[count(i, "accessor index")]
    ctype = acc.componentType
    if not isinstance(ctype, int) or ctype not in COMPONENTS:
        raise FacecleanError(f"accessor {i}: component type {ctype!r} not supported")
    if not isinstance(acc.type, str) or acc.type not in WIDTH:
        raise FacecleanError(f"accessor {i}: type {acc.type!r} not supported")
    dtype, scale = np.dtype(COMPONENTS[ctype][0]), COMPONENTS[ctype][1]
    width, n = WIDTH[acc.type], count(acc.count, f"accessor {i}: count")
    if acc.bufferView is None:
        out = np.zeros((n, width), dtype)
    else:
        out = _elements(model, buffers, acc.bufferView, acc.byteOffset, n, width, dtype, i)
    sparse = acc.sparse
    if sparse is not None and count(sparse.count, f"accessor {i}: sparse count") > 0:
        k, idx, vals = sparse.count, sparse.indices, sparse.values
        if idx.componentType not in SPARSE_INDICES:
            raise FacecleanError(f"accessor {i}: sparse indices must be unsigned integers")
        itype = np.dtype(COMPONENTS[idx.componentType][0])
        rows = _elements(model, buffers, idx.bufferView, idx.byteOffset, k, 1, itype, i)[:, 0]
        if rows.max() >= n:
            raise FacecleanError(f"accessor {i}: a sparse index past its {n} elements")
        out[rows] = _elements(model, buffers, vals.bufferView, vals.byteOffset, k, width, dtype, i)
    if dtype.kind == "f":
        return out.astype(np.float64)
    if scale is not None and (acc.normalized if normalized is None else normalized):
        return decode(out, scale)
    return out


def _elements(
    model: pygltflib.GLTF2,
    buffers: tuple[bytes, ...],
    view_i: object,
    offset: object,
    n: int,
    width: int,
    dtype: np.dtype,
    i: object,
) -> np.ndarray:
    """(n, width) elements of buffer view ``view_i`` from ``offset``, honouring byteStride;
    a copy, after checking every field and that the last element ends inside the buffer."""
    view = model.bufferViews[count(view_i, f"accessor {i}: bufferView")]
    b = count(view.buffer, f"accessor {i}: buffer")
    if b >= len(buffers):
        raise FacecleanError(f"accessor {i}: buffer {b} does not exist")
    for v, what in ((offset, "byteOffset"), (view.byteOffset, "byteOffset"),
                    (view.byteStride, "byteStride")):  # fmt: skip
        if v is not None:
            count(v, f"accessor {i}: {what}")
    item = width * dtype.itemsize
    start = (view.byteOffset or 0) + (offset or 0)
    stride = view.byteStride or item
    data = buffers[b]
    if n == 0:
        return np.zeros((0, width), dtype)
    if start + stride * (n - 1) + item > len(data):
        raise FacecleanError(f"accessor {i}: runs past the end of its buffer")
    a = np.ndarray((n, width), dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize))
    return a.copy()


def decode(raw: np.ndarray, scale: float | None) -> np.ndarray:
    """Stored values -> float64; normalised integers divided by ``scale``, at least -1."""
    a = raw.astype(np.float64)
    return a if scale is None else np.maximum(a / scale, -1.0)


def data_uri(data: bytes) -> str:
    """A buffer as a base64 ``data:`` URI (a ``.gltf`` file's embedded buffer)."""
    return "data:application/octet-stream;base64," + base64.b64encode(data).decode("ascii")


def glb(doc: dict[str, Any], data: bytes | None) -> bytes:
    """A GLB file: the JSON chunk (compact, space-padded), then ``data`` as the BIN chunk
    (zero-padded) unless None. ``doc``'s buffer 0 must be the one without URI."""
    text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), _JSON) + text
    if data is not None:
        data += b"\0" * (-len(data) % 4)
        chunks += struct.pack("<II", len(data), _BIN) + data
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks
