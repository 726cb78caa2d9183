"""The clean / info / convert commands: Live Link files keep every non-value byte."""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.filters import METHODS
from faceclean.io import load
from faceclean.resolve import parse_items
from faceclean.settings import takes_dir

TAKE = takes_dir() / "alexdjulin" / "apfel.csv" if takes_dir() else None
needs_takes = pytest.mark.skipif(TAKE is None, reason="../shared/data/arkit_takes is absent")
CLASSICAL = ["ema", "one-euro", "kalman", "gaussian", "savgol"]


def _have(method: str) -> bool:
    return importlib.util.find_spec(METHODS[method].split(":")[0]) is not None


def _rows(path):
    return [line.split(b",") for line in path.read_bytes().split(b"\n")]


def _assert_only_values_changed(src, out) -> int:
    """Every line equal except blendshape and head/eye angle cells (both cleaned), which
    stay numbers. Returns changed cells."""
    a, b = _rows(src), _rows(out)
    assert len(a) == len(b)
    assert a[0] == b[0]  # header
    blend = {j for j in range(2, len(a[0]))}
    assert len(blend) == 52 + 9
    changed = 0
    for ra, rb in zip(a[1:], b[1:], strict=True):
        assert len(ra) == len(rb)
        for j, (x, y) in enumerate(zip(ra, rb, strict=True)):
            if j in blend:
                assert len(y.split(b".")[1]) == 10  # the source's number format
                changed += x != y
            else:
                assert x == y  # timecode and count as text
    return changed


@needs_takes
@pytest.mark.parametrize("method", CLASSICAL)
def test_clean_livelink_changes_only_values(tmp_path, capsys, method):
    if not _have(method):
        pytest.skip(f"{method} cleaner not written yet")
    out = tmp_path / "out.csv"
    assert main(["clean", str(TAKE), "-o", str(out), "--method", method]) == 0
    said = capsys.readouterr().out
    assert said.count("\n") == 1 and "1926 frames" in said and method in said
    assert _assert_only_values_changed(TAKE, out) > 1000
    cleaned = load(out)
    assert cleaned.meta["format"] == "livelink"
    assert np.array_equal(cleaned.valid, load(TAKE).valid)


@needs_takes
def test_clean_in_place_and_set_params(tmp_path, capsys):
    if not _have("ema"):
        pytest.skip("ema cleaner not written yet")
    take = tmp_path / "take.csv"
    shutil.copyfile(TAKE, take)
    assert (
        main(
            [
                "clean",
                str(take),
                "-o",
                str(take),
                "--method",
                "ema",
                "--set",
                "tau=0.05",
                "--in-place",
            ]
        )
        == 0
    )
    assert "tau=0.05" in capsys.readouterr().out
    assert _assert_only_values_changed(TAKE, take) > 1000
    assert [p.name for p in tmp_path.iterdir()] == ["take.csv"]  # no temporary left


@needs_takes
def test_clean_with_preset(tmp_path, capsys):
    if importlib.util.find_spec("faceclean.filters.presets") is None or not _have("ema"):
        pytest.skip("presets not written yet")
    preset = tmp_path / "p.json"
    preset.write_text(
        json.dumps({"format": "faceclean-preset/1", "method": "ema", "params": {"tau": 0.03}})
    )
    out = tmp_path / "out.json"
    assert main(["clean", str(TAKE), "-o", str(out), "--preset", str(preset)]) == 0
    assert "cleaned with ema (preset" in capsys.readouterr().out
    assert load(out).meta["format"] == "json"
    # --set overrides the preset: a longer time constant smooths more
    slow = tmp_path / "slow.json"
    assert (
        main(["clean", str(TAKE), "-o", str(slow), "--preset", str(preset), "--set", "tau=0.3"])
        == 0
    )
    rough = lambda a: np.nanmean(np.diff(a.values, 2, axis=0) ** 2)  # noqa: E731
    assert rough(load(slow)) < rough(load(out))


@needs_takes
def test_convert_and_info(tmp_path, capsys):
    npz = tmp_path / "take.npz"
    assert main(["convert", str(TAKE), "-o", str(npz)]) == 0
    assert "livelink -> npz" in capsys.readouterr().out
    assert (
        main(["convert", str(npz), "-o", str(tmp_path / "back.csv"), "--format", "livelink"]) == 0
    )
    back, src = load(tmp_path / "back.csv"), load(TAKE)
    np.testing.assert_allclose(back.arkit()[0], src.arkit()[0], atol=1e-12)
    # the timecodes are rebuilt from times + timecode_start, to the ms of a sub-frame
    assert [r[0] for r in _rows(tmp_path / "back.csv")] == [r[0] for r in _rows(TAKE)]
    capsys.readouterr()
    assert main(["info", str(TAKE), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["frames"] == 1926 and facts["missing_frames"] == 35
    assert facts["channels"] == 52 and facts["arkit_absent"] == [] and facts["not_arkit"] == []
    assert facts["rate_hz"] == pytest.approx(30.0, abs=0.01)
    assert facts["dropped_frames"] == 2 and len(facts["gaps"]) == 2
    assert [o["channel"] for o in facts["outside_0_1"]] == ["EyeLookInLeft", "EyeLookOutRight"]
    assert main(["info", str(TAKE)]) == 0
    text = capsys.readouterr().out
    assert "35 missing" in text and "2 channels outside [0, 1]" in text


def _bad_cases(tmp_path):
    garbage = tmp_path / "garbage.csv"
    garbage.write_bytes(b"\x00\xffnot,a,capture\n1,2\n")
    unknown = tmp_path / "take.txt"
    unknown.write_text("hello")
    broken = tmp_path / "broken.csv"
    broken.write_bytes(b"Timecode,BlendshapeCount,JawOpen\n00:00:00:00.000,1,zz\n")
    good = tmp_path / "good.csv"
    good.write_bytes(b"time,jawOpen\n0.0,0.5\n0.1,0.6\n")
    return [
        ([str(tmp_path / "nope.csv")], tmp_path / "o.csv", "no such file"),
        ([str(unknown)], tmp_path / "o.csv", "unknown file type"),
        ([str(garbage)], tmp_path / "o.csv", "not a Live Link Face CSV"),
        ([str(broken)], tmp_path / "o.csv", "not a number"),
        ([str(good)], tmp_path / "missing" / "o.csv", "output folder does not exist"),
        ([str(good)], tmp_path / "o.xyz", "unknown output type"),
    ]


@pytest.mark.parametrize("command", ["clean", "convert", "info"])
def test_bad_input_exit_2_one_line_no_output(tmp_path, capsys, command):
    for args, out, message in _bad_cases(tmp_path):
        if command == "info" and "output" in message:
            continue
        argv = [command, *args] + ([] if command == "info" else ["-o", str(out)])
        if command == "clean":
            argv += ["--method", "ema"]
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("faceclean: ") and err.count("\n") == 1 and message in err, err
        assert not out.exists()
    leftovers = [p.name for p in tmp_path.rglob("*") if p.name.startswith(".")]
    assert leftovers == []


def test_bad_method_and_params(tmp_path, capsys):
    good = tmp_path / "good.csv"
    good.write_bytes(b"time,jawOpen\n0.0,0.5\n0.1,0.6\n")
    out = tmp_path / "o.csv"
    assert main(["clean", str(good), "-o", str(out), "--method", "nope"]) == 2
    assert "unknown method" in capsys.readouterr().err
    assert main(["clean", str(good), "-o", str(out), "--set", "novalue"]) == 2
    assert "KEY=VALUE" in capsys.readouterr().err
    assert main(["clean", str(good), "-o", str(out), "--preset", "x", "--method", "ema"]) == 2
    assert not out.exists()


def test_parse_params():
    got = parse_items(["a=1", "b=2.5", "c=true", "d=off", "e=[1, 2]", "f=name", "g-h=-3e-2"])
    assert all(pattern is None for pattern, _, _ in got)
    assert {k: v for _, k, v in got} == {
        "a": 1, "b": 2.5, "c": True, "d": False, "e": [1, 2], "f": "name", "g_h": -0.03
    }  # fmt: skip
    with pytest.raises(FacecleanError):
        parse_items(["=3"])


@needs_takes
def test_subprocess_entry_point(tmp_path):
    out = tmp_path / "o.json"
    run = subprocess.run(
        [sys.executable, "-m", "faceclean", "convert", str(TAKE), "-o", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    assert "1926 frames" in run.stdout
    assert json.loads(out.read_text())["format"] == "faceclean-animation/1"
    bad = subprocess.run(
        [sys.executable, "-m", "faceclean", "info", str(tmp_path / "none.csv")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert (
        bad.returncode == 2
        and bad.stderr.strip() == f"faceclean: no such file: {tmp_path / 'none.csv'}"
    )


def test_progress_path_equals_batch_clean():
    from faceclean.animation import Animation
    from faceclean.cli.clean_take import PROGRESS_FRAMES, clean_with_progress
    from faceclean.resolve import resolve

    if not _have("one-euro"):
        pytest.skip("one-euro cleaner not written yet")
    n = PROGRESS_FRAMES + 10
    rng = np.random.default_rng(3)
    values = rng.random((n, 3))
    values[100:110] = np.nan  # tracking loss
    anim = Animation(np.arange(n) / 60.0, values, ("jawOpen", "eyeBlinkLeft", "custom"))
    cleaner = resolve("one-euro").build(anim.names)
    stepped = clean_with_progress(cleaner, anim)
    batch = cleaner.clean(anim)
    assert np.array_equal(stepped.values, batch.values, equal_nan=True)
    assert np.isnan(stepped.values[100:110]).all()
    done = []  # a stream cleaner's own clean reports its progress: every valid frame once
    again = cleaner.clean(anim, progress=done.append)
    assert np.array_equal(again.values, batch.values, equal_nan=True)
    assert sum(done) == n - 10 and len(done) > 1


def test_clean_compress_deflates_npz_and_refuses_other_outputs(tmp_path, capsys):
    import zipfile

    from faceclean import Animation, load, save
    from faceclean.channels import ARKIT52

    src = tmp_path / "in.npz"
    rng = np.random.default_rng(0)
    save(Animation(np.arange(30) / 60.0, rng.random((30, 52)), ARKIT52), src)
    assert main(["clean", str(src), "-o", str(tmp_path / "o.npz"), "--compress"]) == 0
    with zipfile.ZipFile(tmp_path / "o.npz") as z:
        assert {m.compress_type for m in z.infolist()} == {zipfile.ZIP_DEFLATED}
    assert main(["clean", str(src), "-o", str(tmp_path / "p.npz")]) == 0
    np.testing.assert_array_equal(load(tmp_path / "o.npz").values, load(tmp_path / "p.npz").values)
    capsys.readouterr()
    assert main(["clean", str(src), "-o", str(tmp_path / "o.csv"), "--compress"]) == 2
    assert capsys.readouterr().err == "faceclean: o.csv: --compress is for npz output, not csv\n"
    assert not (tmp_path / "o.csv").exists()


@needs_takes
def test_an_output_written_over_is_said_replaced_never_in_silence(tmp_path, capsys):
    src = tmp_path / "take.csv"
    shutil.copy(TAKE, src)
    other = tmp_path / "other.csv"  # another raw take, named as the output
    shutil.copy(TAKE, other)
    other.chmod(0o644)  # (writable: a read-only one is refused, "nothing replaces it unasked")
    fresh = tmp_path / "fresh.csv"
    for out, said in ((fresh, "wrote"), (other, "replaced"), (fresh, "replaced")):
        assert main(["clean", str(src), "-o", str(out)]) == 0
        assert capsys.readouterr().out.startswith(f"{said} {out}: "), said
    calib = tmp_path / "calib.json"
    for said in ("wrote", "replaced"):
        assert main(["calibrate", str(src), "-o", str(calib)]) == 0
        assert capsys.readouterr().out.startswith(f"{said} {calib}: "), said
    for said in ("wrote", "replaced"):
        assert main(["convert", str(src), "-o", str(tmp_path / "t.npz")]) == 0
        assert capsys.readouterr().out.startswith(f"{said} "), said
    syn, noisy, truth = (tmp_path / f"{n}.csv" for n in ("syn", "noisy", "truth"))
    corrupt = ["corrupt", str(syn), "-o", str(noisy), "--truth-out", str(truth), "--seed", "1"]
    for said in ("wrote", "replaced"):  # every other writer says it too
        for argv in (["synth", "-o", str(syn), "--seconds", "2"], corrupt,
                     ["plot", str(noisy), "-o", str(tmp_path / "p.png"), "--method", "ema"],
                     ["tune", str(noisy), "--truth", str(truth), "--method", "ema", "-o",
                      str(tmp_path / "t.json")]):  # fmt: skip
            assert main(argv) == 0, argv
            shown = capsys.readouterr().out
            assert f"{said} " in shown and ("replaced" in shown) == (said == "replaced"), shown
    assert main(corrupt) == 0 and f"; replaced {truth}: the truth" in capsys.readouterr().out


def test_a_format_its_output_s_name_contradicts_is_refused_and_the_take_kept(tmp_path, capsys):
    # an npz named .csv (or a Live Link CSV named .json) is a file no reader takes back;
    # with --in-place it would have replaced a readable take with it
    from faceclean import io
    from faceclean.animation import Animation
    from faceclean.channels import ARKIT52

    src = tmp_path / "a.csv"
    io.save(Animation(np.arange(30) / 30, np.full((30, 52), 0.2), ARKIT52), src)
    before = src.read_bytes()
    s = str(src)
    for argv in (["clean", s, "-o", str(tmp_path / "o.csv"), "--format", "npz"],
                 ["clean", s, "-o", str(tmp_path / "o.json"), "--format", "livelink"],
                 ["clean", s, "-o", str(tmp_path / "o"), "--format", "gltf"],
                 ["clean", s, "--in-place", "--format", "npz"],
                 ["convert", s, "-o", s, "--in-place", "--format", "npz"]):  # fmt: skip
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--format" in err and "name the output" in err
    assert src.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"]
    assert main(["clean", str(src), "-o", str(tmp_path / "o.npz"), "--format", "npz"]) == 0
