"""JSON and NPZ: exact float64 round trips on real takes, layouts as documented."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceclean.animation import Animation
from faceclean.errors import FacecleanError
from faceclean.io import detect, load, save
from faceclean.settings import data_dir, takes_dir

TAKES = ["alexdjulin/apfel.csv", "jmtechart/MySlate_3_iPhone.csv"]
needs_takes = pytest.mark.skipif(takes_dir() is None, reason="../shared/data/arkit_takes is absent")


@needs_takes
@pytest.mark.parametrize("ext", ["json", "npz"])
@pytest.mark.parametrize("name", TAKES)
def test_real_take_round_trip_exact(tmp_path, name, ext):
    src = load(takes_dir() / name)
    out = tmp_path / f"take.{ext}"
    save(src, out)
    assert detect(out) == ext
    back = load(out)
    assert back.meta["format"] == ext
    assert back.names == src.names
    assert np.array_equal(back.times, src.times)
    assert np.array_equal(back.values, src.values, equal_nan=True)
    assert np.array_equal(back.meta["pose"], src.meta["pose"], equal_nan=True)
    assert back.meta["pose_names"] == src.meta["pose_names"]
    assert back.meta["timecode_start"] == src.meta["timecode_start"]


def test_json_layout_literal(tmp_path):
    path = tmp_path / "a.json"
    path.write_text(
        '{"format": "faceclean-animation/1", "channels": ["jawOpen", "x"],'
        ' "times": [0.0, 0.5, 1.0], "values": [[0.25, 1], null, [null, 2]]}'
    )
    anim = load(path)
    assert anim.names == ("jawOpen", "x")
    assert not anim.valid[1] and np.isnan(anim.values[2, 0]) and anim.values[2, 1] == 2.0
    out = tmp_path / "b.json"
    save(anim, out)
    doc = json.loads(out.read_text())
    assert doc["values"] == [[0.25, 1.0], [None, None], [None, 2.0]]
    assert doc["times"] == [0.0, 0.5, 1.0] and "pose" not in doc


def test_npz_layout_and_no_pickle(tmp_path):
    anim = Animation([0.0, 0.1], [[0.5, np.nan], [0.25, 1.0]], ("jawOpen", "custom"))
    out = tmp_path / "a.npz"
    save(anim, out)
    with np.load(out, allow_pickle=False) as z:
        assert sorted(z.files) == ["format", "names", "times", "values"]
        assert str(z["format"]) == "faceclean-animation/1"
        assert z["names"].dtype.kind == "U"
    # an object array (pickle) is refused, not executed
    bad = tmp_path / "bad.npz"
    np.savez(bad, times=np.zeros(1), values=np.zeros((1, 1)), names=np.array([{}], dtype=object))
    with pytest.raises(FacecleanError):
        load(bad)


@pytest.mark.skipif(data_dir() is None, reason="../shared/data is absent")
def test_reads_the_raw_stream_npz():
    anim = load(data_dir() / "raw_streams" / "llv_dao.npz")
    assert anim.values.shape == (180, 52)
    assert anim.meta["pose"].shape == (180, 9)


@pytest.mark.parametrize(
    "ext, data, message",
    [
        ("json", b"{not json", "not valid JSON"),
        ("json", b'{"format": "other"}', "not a faceclean-animation/1"),
        (
            "json",
            b'{"format": "faceclean-animation/1", "channels": ["a"], "times": [0],'
            b' "values": [[1, 2]]}',
            "expected 1 x 1",
        ),
        ("npz", b"PK\x03\x04garbage", "npz"),
    ],
)
def test_bad_files(tmp_path, ext, data, message):
    path = tmp_path / f"bad.{ext}"
    path.write_bytes(data)
    with pytest.raises(FacecleanError, match=message):
        load(path)


def test_json_refuses_infinity(tmp_path):
    anim = Animation([0.0], [[np.inf]], ("a",))
    with pytest.raises(FacecleanError, match="infinite"):
        save(anim, tmp_path / "a.json")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("held", [0, 1000])
def test_npz_whose_header_claims_more_than_it_holds_is_refused_unallocated(tmp_path, held):
    """An .npy header claiming 2.2 GiB in a small member: refused before numpy allocates."""
    import struct
    import zipfile

    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (300000000,), }".ljust(118)
    npy = b"\x93NUMPY\x01\x00" + struct.pack("<H", 119) + (header + "\n").encode()
    path = tmp_path / "a.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("times.npy", npy + bytes(held))
    with pytest.raises(FacecleanError, match=r"times.npy claims \(300000000,\) float64"):
        load(path)


def test_npz_is_written_stored_unless_compress_is_asked(tmp_path):
    """No time on zlib that saves nothing (issue 38): stored members by default, deflated
    with ``compress``; both read back the same numbers."""
    import zipfile

    from faceclean import Animation, load, save
    from faceclean.errors import FacecleanError

    rng = np.random.default_rng(0)
    anim = Animation(np.arange(50) / 60.0, rng.random((50, 3)), ("a", "b", "c"))
    save(anim, tmp_path / "plain.npz")
    save(anim, tmp_path / "small.npz", compress=True)
    for name, kind in (("plain.npz", zipfile.ZIP_STORED), ("small.npz", zipfile.ZIP_DEFLATED)):
        with zipfile.ZipFile(tmp_path / name) as z:
            assert {m.compress_type for m in z.infolist()} == {kind}
        back = load(tmp_path / name)
        np.testing.assert_array_equal(back.values, anim.values)
        assert back.values.dtype == np.float64
    with pytest.raises(FacecleanError, match="--compress is for npz output, not csv"):
        save(anim, tmp_path / "x.csv", compress=True)
    assert not (tmp_path / "x.csv").exists()
