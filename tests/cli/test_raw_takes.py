"""Issue 19 section 4: a raw take is never overwritten by accident.

``clean IN -o IN`` (through ``./``, a symlink or a hard link too) and a batch into the
input folder are refused in one line unless ``--in-place``; a folder input with
``-o name.csv`` is refused instead of making a folder called ``name.csv``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.cli import main


def one_line(capsys, *want: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("faceclean: "), err
    for w in want:
        assert w in err[0], err[0]
    return err[0]


@pytest.fixture
def take(tmp_path) -> Path:
    t = np.arange(90) / 60.0
    rng = np.random.default_rng(0)
    x = np.clip(0.4 + 0.05 * rng.standard_normal((90, 52)), 0, 1)
    p = tmp_path / "takes" / "take.csv"
    p.parent.mkdir()
    io.save(Animation(t, x, ARKIT52, {"format": "csv"}), p)
    return p


def _spellings(take: Path) -> dict[str, str]:
    """Other names of the same file: ./, a symlink, a hard link."""
    link, hard = take.parent / "link.csv", take.parent / "hard.csv"
    link.symlink_to(take.name)
    os.link(take, hard)
    dotted = os.path.join(os.path.dirname(take), ".", take.name)
    return {"same": str(take), "dot": dotted, "symlink": str(link), "hardlink": str(hard)}


@pytest.mark.parametrize("spelling", ["same", "dot", "symlink", "hardlink"])
def test_clean_onto_its_input_is_refused_unless_in_place(take, capsys, spelling):
    out = _spellings(take)[spelling]
    before = take.read_bytes()
    assert main(["clean", str(take), "-o", out, "--method", "ema"]) == 2
    one_line(capsys, "is the input", "--in-place")
    assert take.read_bytes() == before  # the raw take is untouched
    assert main(["clean", str(take), "-o", out, "--method", "ema", "--in-place"]) == 0
    assert io.load(out).n_frames == 90 and Path(out).read_bytes() != before


def test_in_place_without_output_replaces_the_one_input(take, capsys):
    before = take.read_bytes()
    assert main(["clean", str(take), "--method", "ema"]) == 2
    one_line(capsys, "-o OUT", "--in-place")
    assert take.read_bytes() == before
    assert main(["clean", str(take), "--method", "ema", "--in-place"]) == 0
    assert take.read_bytes() != before and io.load(take).n_frames == 90


def test_batch_into_the_input_folder_is_refused_unless_in_place(take, capsys):
    folder = take.parent
    before = take.read_bytes()
    for out in (str(folder), str(folder) + "/", f"{folder}/./"):
        assert main(["clean", str(folder), "-o", out, "--method", "ema"]) == 2
        one_line(capsys, "is the input", "would overwrite raw takes", "--in-place")
        assert take.read_bytes() == before
    # the files given one by one into their own folder: the same refusal
    assert main(["clean", str(take), str(take), "-o", f"{folder}/", "--method", "ema"]) == 2
    capsys.readouterr()
    assert main(["clean", str(folder), "-o", f"{folder}/", "--method", "ema", "--in-place"]) == 0
    assert take.read_bytes() != before


def test_batch_to_another_folder_is_unaffected(take, tmp_path, capsys):
    assert main(["clean", str(take.parent), "-o", str(tmp_path / "out"), "--method", "ema"]) == 0
    assert io.load(tmp_path / "out" / "take.csv").n_frames == 90


@pytest.mark.parametrize("name", ["name.csv", "name.glb", "name.json"])
def test_a_folder_input_with_a_file_output_is_refused(take, tmp_path, capsys, name):
    assert main(["clean", str(take.parent), "-o", str(tmp_path / name), "--method", "ema"]) == 2
    one_line(capsys, "a folder input", "names a file", "give a folder")
    assert not (tmp_path / name).exists()  # no folder called name.csv


def test_several_inputs_with_a_file_output_are_refused(take, tmp_path, capsys):
    other = tmp_path / "other.csv"
    other.write_bytes(take.read_bytes())
    assert main(["clean", str(take), str(other), "-o", str(tmp_path / "x.csv")]) == 2
    one_line(capsys, "several inputs", "give a folder")
    assert not (tmp_path / "x.csv").exists()
