"""``faceclean track``'s outputs (red team): a batch writes only inside its folder and
never one file twice (raw scores included); ``--camera --record`` says what it will
replace, refuses recording onto the video it reads before it starts, and a camera index
out of range is one line."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

from faceclean import io
from faceclean.cli import main

sys.path.insert(0, str(Path(__file__).parents[1] / "relay"))
from test_relay_loopback import vmc_peer  # noqa: E402  (the relay tests' python-osc peer)


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.startswith("faceclean:")]
    assert len(lines) == 1 and "Traceback" not in err and "internal error" not in err, err
    return lines[0]


def test_a_batch_refuses_a_symlink_in_its_folder_for_takes_and_raw_files(face_video, tmp_path,
                                                                        capsys):  # fmt: skip
    other = tmp_path / "other.mp4"
    other.write_bytes(Path(face_video).read_bytes())
    victim = tmp_path / "victim.txt"
    victim.write_text("victim\n")
    out = tmp_path / "out"
    out.mkdir()
    for name, extra in (("face.csv", []), ("other.raw.csv", ["--keep-raw"])):
        link = out / name
        link.symlink_to(victim)
        assert main(["track", face_video, str(other), "-o", f"{out}/", *extra]) == 2, name
        line = _one_line(capsys.readouterr().err)
        assert f"{link} is a symbolic link: a batch writes only inside {out}/" in line, line
        assert victim.read_text() == "victim\n" and link.is_symlink()
        assert sorted(p.name for p in out.iterdir()) == [name]  # nothing tracked, no temp
        link.unlink()


def test_a_batch_refuses_a_raw_file_that_is_another_videos_take(face_video, tmp_path, capsys):
    videos = tmp_path / "kr"
    videos.mkdir()
    a, a_raw = videos / "a.mp4", videos / "a.raw.mp4"
    for v in (a, a_raw):
        v.write_bytes(Path(face_video).read_bytes())
    out = tmp_path / "kout"
    argv = ["track", str(a), str(a_raw), "-o", f"{out}/", "--keep-raw"]
    assert main(argv) == 2
    line = _one_line(capsys.readouterr().err)
    assert f"{a} (its raw scores) and {a_raw} would both write {out / 'a.raw.csv'}" in line
    assert not out.exists()  # refused before any work: no folder, no file
    assert main(["track", str(a_raw), str(a), "-o", f"{out}/", "--keep-raw"]) == 2  # either order
    assert "would both write" in _one_line(capsys.readouterr().err) and not out.exists()


def test_live_record_says_what_it_will_replace_and_help_names_the_file(face_video, tmp_path,
                                                                      capsys):  # fmt: skip
    record = tmp_path / "rec.csv"
    cleaned = tmp_path / "rec.clean.csv"
    record.write_text("old take\n")
    cleaned.write_text("old cleaned\n")
    with vmc_peer() as peer:
        url = f"vmc://127.0.0.1:{peer.port}"
        assert main(["track", "--camera", face_video, "--send", url, "--record", str(record)]) == 0
    captured = capsys.readouterr()
    assert f"--record will replace {record} and {cleaned} when the tracking stops" in captured.err
    assert f"{record} (raw, replaced), {cleaned} (cleaned, replaced)" in captured.out
    assert io.load(record).n_frames == io.load(cleaned).n_frames > 0
    with contextlib.suppress(SystemExit):
        main(["track", "--help"])
    said = " ".join(capsys.readouterr().out.split())  # argparse wraps the help
    assert "take.csv -> take.clean.csv" in said and "FILE.clean," not in said


def test_live_refuses_a_camera_index_out_of_range_in_one_line(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "FACECLEAN_DEBUG"}
    for camera in ("2147483648", "-1", "100"):
        argv = ["track", "--camera", camera, "--send", "livelink://127.0.0.1:40001"]
        r = subprocess.run([sys.executable, "-m", "faceclean", *argv], capture_output=True,
                           text=True, env=env, cwd=tmp_path, timeout=120)  # fmt: skip
        assert r.returncode == 2, (camera, r.stderr[-800:])
        line = _one_line(r.stderr)
        assert f"--camera {camera}: a camera index is 0 to 99" in line, line
        assert "video file's path" in line and "no such file" not in line, line


def test_live_refuses_recording_onto_the_video_it_reads_before_it_starts(face_video, tmp_path,
                                                                        capsys):  # fmt: skip
    cam = tmp_path / "cam.csv"  # a video, named as a take
    cam.write_bytes(Path(face_video).read_bytes())
    before = cam.read_bytes()
    with vmc_peer() as peer:
        argv = ["--camera", str(cam), "--send", f"vmc://127.0.0.1:{peer.port}",
                "--record", str(cam)]  # fmt: skip
        assert main(["track", *argv]) == 2
    captured = capsys.readouterr()
    line = _one_line(captured.err)
    assert f"--record: output {cam} is a file this command reads" in line, line
    assert "track camera" not in captured.out and not peer.frames  # refused before starting
    assert cam.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam.csv"]


def test_keep_raw_says_when_it_replaces_the_raw_scores(face_video, tmp_path, capsys):
    # The take and its raw scores are written together, and a raw file written over is
    # said as the take is, never in silence.
    out, raw = tmp_path / "t.csv", tmp_path / "t.raw.csv"
    for path in (out, raw):
        path.write_text("old\n")
    assert main(["track", face_video, "-o", str(out), "--keep-raw"]) == 0
    said = capsys.readouterr().out
    assert f"replaced {out}:" in said and f"raw scores in {raw} (replaced)" in said, said
    assert io.load(raw).n_frames == io.load(out).n_frames > 0
