"""``faceclean track`` on files: every format, --keep-raw, a batch with --jobs, bad input."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import BLANK, N_FRAMES

from faceclean import io
from faceclean.cli import main


def _one_line(err: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.startswith("faceclean:")]
    assert len(lines) == 1 and "Traceback" not in err


def test_track_writes_a_clean_take_with_head_angles_and_the_raw_beside(face_video, tmp_path,
                                                                      capsys):  # fmt: skip
    out = tmp_path / "take.csv"
    assert main(["track", face_video, "-o", str(out), "--keep-raw"]) == 0
    said = capsys.readouterr().out
    assert f"wrote {out}: {N_FRAMES} frames ({len(BLANK)} without a face" in said
    take, raw = io.load(out), io.load(tmp_path / "take.raw.csv")
    assert take.meta["format"] == raw.meta["format"] == "livelink"
    for anim in (take, raw):
        missing = np.flatnonzero(~anim.valid)
        assert tuple(missing) == BLANK
        names = list(anim.meta["pose_names"])
        yaw = anim.meta["pose"][:, names.index("HeadYaw")]
        assert np.abs(yaw[~np.isin(np.arange(N_FRAMES), BLANK)]).max() > 0.2  # rad
    x, y = raw.arkit()[0], take.arkit()[0]
    assert np.nanmax(np.abs(x - y)) > 0.01  # cleaned: not the raw scores again


@pytest.mark.parametrize("name", ["take.json", "take.npz", "take.glb"])
def test_track_writes_every_format(face_video, tmp_path, name):
    out = tmp_path / name
    assert main(["track", face_video, "-o", str(out), "--method", "one-euro"]) == 0
    anim = io.load(out)
    assert "HeadYaw" in list(anim.meta["pose_names"])  # the GLB's head node, the others' pose
    assert np.isfinite(anim.values).any()


def test_a_batch_runs_jobs_and_a_bad_video_fails_alone(face_video, tmp_path, capsys):
    bad = tmp_path / "bad.mp4"
    bad.write_text("no video here\n" * 20)
    other = tmp_path / "other.mp4"
    other.write_bytes(Path(face_video).read_bytes())
    outdir = tmp_path / "out"
    code = main(["track", face_video, str(other), str(bad), "-o", f"{outdir}/", "--jobs", "2"])
    assert code == 1
    captured = capsys.readouterr()
    assert "tracked 2 of 3 videos" in captured.out and "bad.mp4" in captured.err
    assert sorted(os.listdir(outdir)) == ["face.csv", "other.csv"]  # nothing for the bad one
    assert io.load(outdir / "face.csv").n_frames == N_FRAMES


def test_bad_input_is_one_line_and_writes_nothing(face_video, rendered, tmp_path, capsys):
    from conftest import write_video

    text = tmp_path / "notes.mp4"
    text.write_text("hello\n")
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    blank = write_video(tmp_path / "blank.mp4", rendered[:4], 30, blank=range(4))
    before = Path(face_video).read_bytes()
    cases = [
        ([str(text), "-o", str(tmp_path / "a.csv")], "not a video"),
        ([str(tmp_path / "gone.mp4"), "-o", str(tmp_path / "a.csv")], "no such file"),
        ([face_video, "-o", face_video], "reads"),
        ([face_video, "-o", str(fifo)], "FIFO|fifo|named pipe"),
        ([blank, "-o", str(tmp_path / "a.csv")], "no face found"),
        ([face_video, "-o", str(tmp_path / "a.txt")], "unknown output type"),
        (["--camera", face_video], "--send"),
    ]
    for argv, words in cases:
        assert main(["track", *argv]) == 2, argv
        err = capsys.readouterr().err
        _one_line(err)
        assert __import__("re").search(words, err), (argv, err)
    assert not (tmp_path / "a.csv").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temp
    assert Path(face_video).read_bytes() == before


def test_track_does_not_import_torch(face_video, tmp_path):
    code = (
        "import sys; from faceclean.cli import main; "
        f"rc = main(['track', {face_video!r}, '-o', {str(tmp_path / 't.csv')!r}]); "
        "assert rc == 0, rc; assert 'torch' not in sys.modules, 'torch imported'"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]


def test_two_faces_in_view_the_first_largest_is_kept_said_once_and_exit_1(two_faces,
                                                                          face_video, tmp_path,
                                                                          capsys):  # fmt: skip
    from conftest import two_jaws, write_video

    video = write_video(tmp_path / "two.mp4", two_faces, 30)
    out = tmp_path / "two.csv"
    assert main(["track", video, "-o", str(out), "--keep-raw"]) == 1  # issue 36: not 0
    said = capsys.readouterr().out
    crowd = [ln for ln in said.splitlines() if "faces in view" in ln]
    assert len(crowd) == 1 and "on the left of the picture" in crowd[0], said
    assert f"wrote {out}: {N_FRAMES} frames" in said  # written all the same
    for path in (out, tmp_path / "two.raw.csv"):  # whole and loadable
        anim = io.load(path)
        assert anim.n_frames == N_FRAMES and anim.valid.all(), path
        assert np.isfinite(anim.values).all(), path
    from faceclean.channels import ARKIT52

    jaw = io.load(tmp_path / "two.raw.csv").arkit()[0][:, ARKIT52.index("jawOpen")]
    mine, other = two_jaws(N_FRAMES)
    assert np.isfinite(jaw).all()
    # A's mouth throughout, also once B has become the larger face (from a third on)
    late = slice(N_FRAMES // 3, None)
    assert np.corrcoef(jaw, mine)[0, 1] > 0.9
    assert np.corrcoef(jaw[late], mine[late])[0, 1] > 0.9
    assert np.corrcoef(jaw, other)[0, 1] < -0.5

    # a batch: every video tracked and written whole, exit 1 because one had two faces
    outdir = tmp_path / "out"
    assert main(["track", face_video, video, "-o", f"{outdir}/"]) == 1
    said = capsys.readouterr().out
    assert "tracked 2 of 2 videos" in said, said
    crowd = [ln for ln in said.splitlines() if "faces in view" in ln]
    assert len(crowd) == 1 and crowd[0].startswith(f"{video}: 2 faces in view"), said
    assert sorted(os.listdir(outdir)) == ["face.csv", "two.csv"]
    for name in ("face.csv", "two.csv"):
        assert io.load(outdir / name).n_frames == N_FRAMES, name


def test_track_shows_its_own_lines_not_the_native_libraries_logs(face_video, tmp_path):
    # MediaPipe's graph (absl, TFLite) and OpenCV's ffmpeg wrote a page of lines no user
    # can act on above faceclean's own, on every run and on a bad file
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(np.random.default_rng(0).integers(0, 256, 20000, np.uint8).tobytes())
    native = __import__("re").compile(
        r"\.(cc|cpp|hpp|h):\d+|@ 0x|^W\d{4} |^INFO: |^WARNING: |^\[ ?(WARN|ERROR)"
    )
    env = {k: v for k, v in os.environ.items() if k != "FACECLEAN_DEBUG"}
    runs = [([face_video, "-o", str(tmp_path / "t.csv")], 0),
            ([str(bad), "-o", str(tmp_path / "t.csv")], 2),
            (["--camera", "99", "--send", "vmc://127.0.0.1:9"], 2)]  # no such camera  # fmt: skip
    for argv, code in runs:
        r = subprocess.run([sys.executable, "-m", "faceclean", "track", *argv],
                           capture_output=True, text=True, env=env)  # fmt: skip
        assert r.returncode == code, r.stderr[-800:]
        lines = [p.strip() for ln in r.stderr.splitlines() for p in ln.split("\r")]
        assert not [ln for ln in lines if native.search(ln)], r.stderr[-800:]
