"""`faceclean clean` on several files or folders, and per-channel levels on the command line."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52, INDEX
from faceclean.cli import main
from faceclean.datasets.performer import perform

EMA = ("--method", "ema")


def _take(seed: int, seconds: float = 2.0) -> Animation:
    return perform(seconds, seed, fps=60.0)


def _folder(root):
    """takes/a.csv (Live Link), takes/sub/b.npz, takes/sub/deeper/c.csv (plain),
    takes/sub/broken.csv (a bad row), takes/.hidden.csv, takes/notes.txt."""
    (root / "sub" / "deeper").mkdir(parents=True)
    io.save(_take(1), root / "a.csv", fmt="livelink")
    io.save(_take(2), root / "sub" / "b.npz")
    io.save(_take(3), root / "sub" / "deeper" / "c.csv", fmt="csv")
    good = (root / "a.csv").read_text().splitlines()
    bad = good[:5] + ["garbage,row,that,is,not,a,frame"] + good[5:]
    (root / "sub" / "broken.csv").write_text("\n".join(bad) + "\n")
    (root / ".hidden.csv").write_text("not even csv")
    (root / "notes.txt").write_text("not a take")


def test_a_folder_with_one_broken_file_cleans_the_rest_and_exits_non_zero(tmp_path, capsys):
    src, out = tmp_path / "takes", tmp_path / "out"
    _folder(src)
    before = {p: p.read_bytes() for p in src.rglob("*") if p.is_file()}
    assert main(["clean", str(src), "-o", f"{out}/", *EMA]) == 1
    written = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert written == ["a.csv", "sub/b.npz", "sub/deeper/c.csv"]  # same relative paths
    assert io.load(out / "a.csv").meta["format"] == "livelink"  # same formats
    assert io.load(out / "sub" / "deeper" / "c.csv").meta["format"] == "csv"
    assert io.load(out / "sub" / "b.npz").meta["format"] == "npz"
    for rel in written:  # really cleaned: values differ from the input, frames the same
        a, b = io.load(src / rel), io.load(out / rel)
        assert a.n_frames == b.n_frames and not np.allclose(a.values, b.values)
    assert not list(out.rglob(".*"))  # no temporary file is left
    assert before == {p: p.read_bytes() for p in src.rglob("*") if p.is_file()}  # inputs intact
    text = capsys.readouterr()
    assert "cleaned 3 of 4 files" in text.out
    assert text.out.count("wrote ") == 3 and "FAILED" in text.out
    assert "1 failed" in text.err and "broken.csv" in text.err.split("1 failed")[1]


def test_several_files_into_a_folder_with_jobs(tmp_path, capsys):
    files = []
    for i in range(3):
        files.append(tmp_path / f"take{i}.csv")
        io.save(_take(10 + i), files[-1], fmt="livelink")
    out = tmp_path / "clean"
    assert main(["clean", *map(str, files), "-o", str(out), "--jobs", "2", *EMA]) == 0
    for f in files:  # the same bytes as one file at a time
        one = tmp_path / f"one_{f.name}"
        assert main(["clean", str(f), "-o", str(one), *EMA]) == 0
        assert (out / f.name).read_bytes() == one.read_bytes()
    assert "cleaned 3 of 3 files" in capsys.readouterr().out


def test_a_missing_file_is_a_failure_of_its_own_and_leaves_no_folder(tmp_path, capsys):
    good = tmp_path / "good.csv"
    io.save(_take(4), good, fmt="livelink")
    out = tmp_path / "out"
    assert main(["clean", str(good), str(tmp_path / "absent.csv"), "-o", str(out), *EMA]) == 1
    assert sorted(p.name for p in out.iterdir()) == ["good.csv"]
    assert "no such file" in capsys.readouterr().err


def test_a_failing_file_leaves_a_new_folder_to_a_file_still_cleaning_into_it(tmp_path):
    # CI lost a good file on the cluster: broken.csv failed and removed the new folder sub/
    # while another worker, which had found sub/ there, was still cleaning sub/b.npz.
    from faceclean.batch import plan
    from faceclean.cli import clean_batch, parser

    src, out = tmp_path / "takes", tmp_path / "out"
    _folder(src)
    args = parser().parse_args(["clean", str(src), "-o", f"{out}/", *EMA])
    jobs = {j.src.name: j for j in plan(args.input, args.output)}
    new = clean_batch._new_folders(jobs.values())
    assert new == [out / "sub" / "deeper", out / "sub", out]  # deepest first
    ok, why = clean_batch._clean(args, jobs["broken.csv"])  # makes sub/, fails
    assert not ok and "line 6" in why
    assert (out / "sub").is_dir()  # left to b.npz's task, which may be cleaning into it
    assert clean_batch._clean(args, jobs["b.npz"])[0]
    clean_batch._tidy(new)  # every task ended: only the folder left empty goes
    assert (out / "sub" / "b.npz").is_file() and not (out / "sub" / "deeper").exists()


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--jobs", "0"], "--jobs must be at least 1"),
        (["--format", "npz"], "keeps each file's format"),
        (["--method", "nope"], "nope"),
    ],
)
def test_bad_batch_options_fail_once_before_any_file(tmp_path, capsys, argv, words):
    src = tmp_path / "takes"
    src.mkdir()
    io.save(_take(5), src / "a.csv", fmt="livelink")
    assert main(["clean", str(src), "-o", str(tmp_path / "out"), *argv]) == 2
    assert words in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_two_inputs_that_would_write_one_output_are_refused(tmp_path, capsys):
    for d in ("x", "y"):
        (tmp_path / d).mkdir()
        io.save(_take(6), tmp_path / d / "a.csv", fmt="livelink")
    argv = ["clean", str(tmp_path / "x" / "a.csv"), str(tmp_path / "y" / "a.csv")]
    assert main([*argv, "-o", str(tmp_path / "out"), *EMA]) == 2
    assert "would both write" in capsys.readouterr().err


def test_level_overrides_on_the_command_line_change_exactly_the_named_channels(tmp_path):
    take = tmp_path / "take.npz"
    rng = np.random.default_rng(7)
    io.save(Animation.from_arkit(np.arange(120) / 60.0, rng.uniform(0, 1, (120, 52))), take)
    plain, levelled = tmp_path / "plain.npz", tmp_path / "levels.npz"
    assert main(["clean", str(take), "-o", str(plain), *EMA]) == 0
    sets = ["--set", "eyeBlink*.gain=1.5", "--set", "tongueOut.off", "--set", "jawOpen.clamp=0,0.2"]
    assert main(["clean", str(take), "-o", str(levelled), *EMA, *sets]) == 0
    a, b = io.load(plain).values, io.load(levelled).values
    changed = {ARKIT52[j] for j in np.flatnonzero(np.any(a != b, axis=0))}
    assert changed == {"eyeBlinkLeft", "eyeBlinkRight", "tongueOut", "jawOpen"}
    assert np.all(b[:, INDEX["tongueOut"]] == 0.0) and b[:, INDEX["jawOpen"]].max() <= 0.2
    j = INDEX["eyeBlinkLeft"]  # lifted, and clamped to [0, 1] before the cleaner (issue 19)
    assert b[:, j].max() <= 1.0 and b[:, j].mean() > 1.2 * a[:, j].mean()


def test_level_overrides_stream_a_livelink_file_like_the_whole_file_path(tmp_path):
    take = tmp_path / "take.csv"
    io.save(_take(8), take, fmt="livelink")
    sets = ["--set", "mouth*.gain=1.3", "--set", "browInnerUp.offset=0.1", *EMA]
    streamed, whole = tmp_path / "s.csv", tmp_path / "w.json"
    assert main(["clean", str(take), "-o", str(streamed), *sets]) == 0  # streams (same format)
    assert main(["clean", str(take), "-o", str(whole), *sets]) == 0  # reads it whole
    np.testing.assert_allclose(io.load(streamed).arkit()[0], io.load(whole).arkit()[0], atol=1e-9)


def test_one_file_into_a_folder_needs_the_folders_spelling(tmp_path, capsys):
    take = tmp_path / "take.csv"
    io.save(_take(9), take, fmt="livelink")
    (tmp_path / "out").mkdir()
    assert main(["clean", str(take), "-o", str(tmp_path / "out"), *EMA]) == 2  # a typo?
    assert not any((tmp_path / "out").iterdir())
    assert main(["clean", str(take), "-o", f"{tmp_path / 'out'}/", *EMA]) == 0
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["take.csv"]
    assert main(["clean", str(take), "-o", f"{tmp_path / 'new'}/", *EMA]) == 0  # made
    assert (tmp_path / "new" / "take.csv").is_file()


def test_a_batch_says_it_left_its_earlier_outputs_alone(tmp_path, capsys):
    # third red team: a second batch into a folder inside the input skipped its files unsaid
    takes = tmp_path / "takes"
    takes.mkdir()
    (takes / "a.csv").write_text("time,jawOpen\n0,0.1\n0.1,0.2\n0.2,0.3\n")
    args = ["clean", str(takes), "-o", str(takes / "sub"), "--method", "ema"]
    assert main(args) == 0
    assert "not cleaned again" not in capsys.readouterr().out  # nothing there yet
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "cleaned 1 of 1 files" in out
    assert f"(1 file already in {takes / 'sub'}, inside the input folder, not cleaned again)" in out


def test_a_link_planted_in_the_output_folder_is_refused_never_written_through(tmp_path, capsys):
    src, out = tmp_path / "in", tmp_path / "out"
    (src / "sub").mkdir(parents=True)
    io.save(_take(1), src / "a.csv")
    io.save(_take(2), src / "sub" / "b.csv")
    victim, elsewhere = tmp_path / "victim.csv", tmp_path / "elsewhere"
    victim.write_text("a take of someone else's")
    elsewhere.mkdir()
    out.mkdir()
    for link, target in ((out / "a.csv", victim), (out / "sub", elsewhere)):
        link.symlink_to(target)
        assert main(["clean", str(src), "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"{link} is a symbolic link" in err, err
        link.unlink()
    assert victim.read_text() == "a take of someone else's" and not any(elsewhere.iterdir())
    assert main(["clean", str(src), "-o", str(out)]) == 0  # no link: as before
