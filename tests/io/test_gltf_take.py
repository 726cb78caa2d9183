"""Any take to an animated GLB, checked by real glTF implementations.

The Khronos glTF validator and three.js's GLTFLoader run in node from node_modules
(``npm ci``: gltf-validator is a devDependency, three the report's dependency); Blender's
own importer runs in background mode when Debian's ``blender`` (with ``python3-numpy``)
is installed (.ci/run installs it). Each of those tests skips, saying why, without it.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers import IMPORTERS, REPO

from faceclean.animation import Animation
from faceclean.channels import ARKIT52, INDEX
from faceclean.cli import main
from faceclean.face import mesh as facemesh
from faceclean.io import gltf_take, load, save
from faceclean.settings import data_dir

MESH_NPZ = data_dir() / "meshes" / "arkit_reference_mesh.npz" if data_dir() else None


def _node_missing(package: str) -> str | None:
    if shutil.which("node") is None:
        return "node is not installed (Debian package 'nodejs')"
    if not (REPO / "node_modules" / package / "package.json").is_file():
        return f"node_modules/{package} is absent: run `npm ci` (or `make venv`)"
    return None


def _blender_missing() -> str | None:
    if shutil.which("blender") is None:
        return "blender is not installed (Debian packages 'blender python3-numpy'; .ci/run)"
    return None


needs_validator = pytest.mark.skipif(
    _node_missing("gltf-validator") is not None, reason=str(_node_missing("gltf-validator"))
)
needs_three = pytest.mark.skipif(
    _node_missing("three") is not None, reason=str(_node_missing("three"))
)
needs_blender = pytest.mark.skipif(_blender_missing() is not None, reason=str(_blender_missing()))


def _take(fps: float = 30.0, seconds: float = 2.0) -> Animation:
    """A take with a jaw cycle and a blink, one tracking-loss frame, one repeated
    timestamp, one missing value and no tongueOut column; times start at 5 s."""
    t = 5.0 + np.arange(int(fps * seconds)) / fps
    v = np.zeros((len(t), 52))
    v[:, INDEX["jawOpen"]] = 0.5 - 0.5 * np.cos(2 * np.pi * (t - 5.0) / seconds)
    v[:, INDEX["eyeBlinkLeft"]] = np.exp(-(((t - 6.0) / 0.08) ** 2))
    v[:, INDEX["mouthSmileRight"]] = np.linspace(0.0, 0.8, len(t))
    v[10] = np.nan  # tracking lost
    t[20] = t[19]  # a repeated timestamp
    v[30, INDEX["mouthSmileRight"]] = np.nan  # one value missing
    keep = [n for n in ARKIT52 if n != "tongueOut"]
    return Animation(t, v[:, [INDEX[n] for n in keep]], keep)


def _expected(take: Animation) -> tuple[np.ndarray, np.ndarray]:
    """(times, (K, 52) weights) the documented rule gives for _take()."""
    keep = np.ones(take.n_frames, bool)
    keep[[10, 20]] = False
    w, _ = take.arkit()
    w = w[keep]  # frame 30 is keyframe 28 and holds frame 29's value
    w[28, INDEX["mouthSmileRight"]] = w[27, INDEX["mouthSmileRight"]]
    return (take.times[keep] - take.times[0]).astype(np.float32), w


@pytest.fixture(scope="module")
def glb(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("glb")
    save(_take(), folder / "take.csv", fmt="csv")
    assert main(["convert", str(folder / "take.csv"), "-o", str(folder / "take.glb")]) == 0
    return folder / "take.glb"


def test_keyframes_follow_the_documented_rule():
    take = _take()
    times, weights, counts = gltf_take.keyframes(take)
    want_t, want_w = _expected(take)
    assert counts == {"lost": 1, "unordered": 1, "channels": 51}
    assert times[0] == 0.0 and np.all(np.diff(times) > 0)
    np.testing.assert_array_equal(times, want_t)
    np.testing.assert_allclose(weights, want_w, atol=1e-7)
    assert weights.dtype == np.float32 and not np.isnan(weights).any()


def test_a_cell_past_any_weight_is_held_as_a_missing_one_never_written_as_inf():
    # 1e308 is inf in float32, and glTF's accessors hold finite numbers only
    take = _take()
    v = take.values.copy()
    j = take.names.index("jawOpen")
    v[3:6, j] = [1e308, np.inf, -1e9]
    _, weights, _ = gltf_take.keyframes(take.with_values(v))
    _, clean, _ = gltf_take.keyframes(take)
    assert np.isfinite(weights).all() and np.abs(weights).max() <= 1.0
    k = INDEX["jawOpen"]
    held = weights[:, k][np.abs(weights[:, k] - clean[:, k]) > 1e-7]
    assert len(held) and np.all(np.isin(held, clean[:, k]))  # an earlier frame's value


def test_the_glb_reads_back_as_the_take(glb, capsys):
    back = load(glb)
    want_t, want_w = _expected(_take())
    assert back.names == ARKIT52 and back.meta["interpolation"] == "LINEAR"
    np.testing.assert_allclose(back.times, want_t, atol=1e-6)
    np.testing.assert_allclose(back.values, want_w, atol=1e-6)
    # glTF -> glTF keeps today's behaviour: only the weights accessor changes.
    assert main(["convert", str(glb), "-o", str(glb.with_name("copy.glb"))]) == 0
    assert glb.with_name("copy.glb").read_bytes() == glb.read_bytes()
    assert "(gltf -> gltf)" in capsys.readouterr().out


@pytest.mark.parametrize("fmt,suffix", [("livelink", ".csv"), ("json", ".json"), ("npz", ".npz")])
def test_every_format_converts(tmp_path, fmt, suffix, capsys):
    take = _take()
    src = tmp_path / f"take{suffix}"
    save(take, src, fmt=fmt)
    read = load(src)
    out = tmp_path / "take.glb"
    assert main(["convert", str(src), "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert f"({fmt} -> glb)" in said and "52 morph targets" in said and "ARKit channels" in said
    assert "dropped 1 tracking-loss and 1 non-advancing frames" in said
    times, weights, _ = gltf_take.keyframes(read)
    back = load(out)
    np.testing.assert_allclose(back.times, times, atol=1e-6)
    np.testing.assert_allclose(back.values, weights, atol=1e-6)
    assert np.abs(back.channel("jawOpen")).max() > 0.9


def test_gltf_json_output_and_a_users_mesh(tmp_path):
    src = tmp_path / "take.csv"
    save(_take(), src, fmt="csv")
    small = tmp_path / "small.npz"  # a user's mesh: 3 of its 4 targets have ARKit names
    rng = np.random.default_rng(3)
    v = rng.normal(0, 0.05, (300, 3)).astype(np.float32)
    tri = np.arange(300, dtype=np.uint32).reshape(-1, 3)
    picks = ["jawOpen", "eyeBlinkLeft", "mouthSmileRight"]
    deltas = rng.normal(0, 0.01, (4, 300, 3)).astype(np.float32)
    np.savez(small, neutral_vertices=v, faces=tri, blendshape_deltas=deltas,
             names=np.array([*picks, "notAnArkitShape"]))  # fmt: skip
    out = tmp_path / "small.gltf"
    assert main(["convert", str(src), "-o", str(out), "--mesh", str(small)]) == 0
    doc = json.loads(out.read_text())
    assert doc["buffers"][0]["uri"].startswith("data:application/octet-stream;base64,")
    mesh = doc["meshes"][0]
    assert mesh["extras"]["targetNames"] == list(ARKIT52)
    assert len(mesh["primitives"][0]["targets"]) == 52
    back = facemesh.load(out)
    assert [ARKIT52[i] for i in np.flatnonzero(back.present)] == sorted(picks, key=INDEX.get)
    np.testing.assert_allclose(load(out).values, _expected(_take())[1], atol=1e-6)


def test_refusals_leave_no_output(tmp_path, capsys):
    src = tmp_path / "take.csv"
    save(_take(), src, fmt="csv")
    other = tmp_path / "other.csv"
    other.write_text("time,headYaw\n0,0.1\n0.1,0.2\n")
    lost = tmp_path / "lost.json"
    t = np.arange(3) / 30
    save(Animation.from_arkit(t, np.full((3, 52), np.nan)), lost, fmt="json")
    out = tmp_path / "out.glb"
    out.write_bytes(b"precious")
    cases = [
        ([str(other), "-o", str(out)], "ARKit blendshape"),
        ([str(lost), "-o", str(out)], "tracking loss"),
        ([str(src), "-o", str(out), "--mesh", str(tmp_path / "none.npz")], "no such mesh"),
        ([str(src), "-o", str(out), "--mesh", str(src)], "must be .npz, .glb or .gltf"),
        ([str(src), "-o", str(tmp_path / "x.json"), "--mesh", str(src)], "for glTF output"),
    ]
    for args, why in cases:
        assert main(["convert", *args]) == 2
        err = capsys.readouterr().err
        assert why in err and err.count("\n") == 1, err
    assert out.read_bytes() == b"precious"
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["lost.json", "other.csv", "out.glb", "take.csv"]


def _node(script: str, path: Path) -> dict:
    done = subprocess.run(
        ["node", str(IMPORTERS / script), str(path)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@needs_validator
@pytest.mark.parametrize("kind", ["glb", "gltf", "user mesh", "face-mesh"])
def test_khronos_validator_finds_no_issue(glb, tmp_path, kind):
    path = glb
    if kind == "gltf":
        path = tmp_path / "take.gltf"
        assert main(["convert", str(glb.with_name("take.csv")), "-o", str(path)]) == 0
    elif kind == "user mesh":
        if MESH_NPZ is None or not MESH_NPZ.is_file():
            pytest.skip("../shared/data/meshes/arkit_reference_mesh.npz is absent")
        path = tmp_path / "ref.glb"
        args = [str(glb.with_name("take.csv")), "-o", str(path), "--mesh", str(MESH_NPZ)]
        assert main(["convert", *args]) == 0
    elif kind == "face-mesh":  # the still face, same layout without the animation
        path = tmp_path / "face.glb"
        assert main(["face-mesh", "-o", str(path)]) == 0
    report = _node("validate_gltf.cjs", path)
    issues = report["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"][:5]
    assert report["info"]["hasMorphTargets"]
    assert report["info"]["animationCount"] == (0 if kind == "face-mesh" else 1)


@needs_three
def test_three_js_loads_the_face_and_its_clip(glb):
    got = _node("load_gltf.mjs", glb)
    [mesh] = got["meshes"]
    assert mesh["targets"] == list(ARKIT52) and mesh["influences"] == 52
    [clip] = got["clips"]
    assert clip["name"] == "take"
    [track] = clip["tracks"]
    assert track["name"] == "face.morphTargetInfluences"
    want_t, want_w = _expected(_take())
    np.testing.assert_allclose(track["times"], want_t, atol=1e-6)
    np.testing.assert_allclose(np.reshape(track["values"], (-1, 52)), want_w, atol=1e-6)
    assert clip["duration"] == pytest.approx(want_t[-1], abs=1e-6)


def test_the_file_says_its_rate_and_frame_range(glb, capsys):
    """glTF has no frame rate: the scene's and the animation's extras carry the take's, and
    the frame range at it (docs/FORMATS.md, Frame rate and length)."""
    doc = gltf_take.document(facemesh.stylised(), _take())[0]
    want = {"fps": 30.0, "frame_start": 0, "frame_end": 59}  # 2 s at 30 fps, from 0
    assert doc["scenes"][0]["extras"] == want
    assert {k: doc["animations"][0]["extras"][k] for k in want} == want
    # a 59.94 Hz Live Link take, its timestamps quantised to 1/60000 s (median 59.88 Hz)
    t = np.round((np.arange(600) / 59.94) * 6e4) / 6e4
    t[1::2] += 1 / 6e4
    take = Animation(t, np.full((600, 1), 0.5), ["jawOpen"])
    extras = gltf_take.document(facemesh.stylised(), take)[0]["scenes"][0]["extras"]
    assert extras["fps"] == 59.94 and extras["frame_end"] == round(t[-1] * 59.94) == 599
    # the command says it too
    assert main(["convert", str(glb.with_name("take.csv")), "-o", str(glb.with_name("a.glb"))]) == 0
    assert "at 30 fps (frames 0-59" in capsys.readouterr().out


@pytest.mark.parametrize(
    "rate,named", [(59.88, 59.94), (59.904, 59.94), (29.97, 29.97), (30.02, 30.0), (24.0, 24.0),
                   (37.5, 37.5), (61.0, 61.0), (119.9, 119.88), (33.3333, 33.333)]
)  # fmt: skip
def test_a_measured_rate_takes_the_named_rate_it_is_close_to(rate, named):
    from faceclean.timing import nominal_rate

    assert nominal_rate(rate) == named


@needs_blender
@pytest.mark.parametrize("fps", [30.0, 59.94])
def test_the_documented_blender_script_lands_the_keys_on_the_takes_frames(tmp_path, fps):
    """docs/FORMATS.md's script run in Blender: the scene at the take's rate, its range
    0 .. frame_end, and every key on a whole frame (Blender alone: 24 fps, 1-250)."""
    take = Animation(np.arange(int(12 * fps)) / fps, np.full((int(12 * fps), 1), 0.3), ["jawOpen"])
    take.values[::7] = 0.6
    path = tmp_path / "take.glb"
    with path.open("wb") as f:
        timing = gltf_take.write(take, f, path)
    out = tmp_path / "recipe.json"
    script = IMPORTERS / "blender_recipe.py"
    done = subprocess.run(
        ["blender", "-b", "--factory-startup", "--python", str(script), "--",
         str(REPO / "docs" / "FORMATS.md"), str(path), str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0 and out.is_file(), done.stdout[-2000:] + done.stderr[-2000:]
    got = json.loads(out.read_text())
    n = take.n_frames
    assert got["fps"] == pytest.approx(fps, abs=1e-4) and timing["fps"] == fps
    assert (got["frame_start"], got["frame_end"]) == (0, n - 1) == (0, timing["frame_end"])
    assert got["custom"]["frame_end"] == n - 1  # the scene's extras as custom properties
    np.testing.assert_allclose(got["key_frames"], np.arange(n), atol=1e-3)


@needs_blender
def test_blender_imports_shape_keys_and_their_action(glb, tmp_path):
    out = tmp_path / "blender.json"
    script = IMPORTERS / "blender_gltf.py"
    done = subprocess.run(
        ["blender", "-b", "--factory-startup", "--python", str(script), "--", str(glb), str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0 and out.is_file(), done.stdout[-2000:] + done.stderr[-2000:]
    got = json.loads(out.read_text())
    [mesh] = got["meshes"]
    assert mesh["shape_keys"] == ["Basis", *ARKIT52]
    assert mesh["action"] is not None and mesh["action"].startswith("take")
    curves = {c["path"]: np.array(c["keys"]) for c in mesh["fcurves"]}
    assert len(curves) == 52
    want_t, want_w = _expected(_take())
    for name in ("jawOpen", "eyeBlinkLeft", "mouthSmileRight", "tongueOut"):
        keys = curves[f'key_blocks["{name}"].value']  # (K, 2) [frame, value]
        frames = keys[:, 0] - keys[0, 0]
        np.testing.assert_allclose(frames / got["fps"], want_t, atol=1e-4)
        np.testing.assert_allclose(keys[:, 1], want_w[:, INDEX[name]], atol=1e-6)


@pytest.mark.parametrize("times", [[0.0, 1e39], [-1e300, 0.0], [1e300, 1.0000000000001e300]])
def test_times_glTF_cannot_hold_are_refused_in_one_line(tmp_path, capsys, times):
    # red team: float32 key times overflowed to inf and the rate to NaN (internal error)
    src, out = tmp_path / "t.csv", tmp_path / "t.glb"
    src.write_text("time,jawOpen\n" + "".join(f"{t!r},0.{k + 1}\n" for k, t in enumerate(times)))
    assert main(["convert", str(src), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "glTF keyframe times" in err and not out.exists()


@pytest.mark.parametrize(
    "times,kept",
    [([0.0, 86400.0], 2),  # a day between two frames: 1e-5 Hz
     ([0.0, 1e-300, 2e-300], 1),  # steps float32 cannot tell apart
     ([10.0, 9.0, 8.0, 7.0], 1)],  # backwards
)  # fmt: skip
def test_a_take_with_no_usable_rate_gets_no_timing_and_a_sane_line(tmp_path, capsys, times, kept):
    src, out = tmp_path / "t.csv", tmp_path / "t.glb"
    src.write_text("time,jawOpen\n" + "".join(f"{t!r},0.5\n" for t in times))
    assert main(["convert", str(src), "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert f"wrote {out}: {kept} keyframes over " in said and " fps" not in said
    assert "over -" not in said and "nan" not in said and "inf" not in said
    doc = gltf_take.document(facemesh.stylised(), load(src))[0]
    assert "extras" not in doc["scenes"][0]
