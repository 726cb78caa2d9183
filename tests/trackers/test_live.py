"""``faceclean track --camera FILE --send URL``: the live path over loopback, a real peer
(python-osc for VMC, a UDP socket + our Live Link decoder), a file standing in for the
camera (none exists here)."""

from __future__ import annotations

import socket
import sys
import threading
from pathlib import Path

import numpy as np
from conftest import BLANK, N_FRAMES

from faceclean import io
from faceclean.cli import main

sys.path.insert(0, str(__import__("pathlib").Path(__file__).parents[1] / "relay"))
from test_relay_loopback import vmc_peer  # noqa: E402  (the relay tests' python-osc peer)


def test_camera_frames_are_tracked_cleaned_and_sent_over_vmc(face_video, tmp_path, capsys):
    record = tmp_path / "session.csv"
    with vmc_peer() as peer:
        url = f"vmc://127.0.0.1:{peer.port}"
        assert main(["track", "--camera", face_video, "--send", url, "--record", str(record)]) == 0
        peer.wait_for(N_FRAMES - len(BLANK) - 3)
    said = capsys.readouterr().out
    assert "stopped: camera 30 dropped" in said
    dropped = int(said.split("stopped: camera 30 dropped ")[1].split()[0])
    sent = int(said.split(" sent ")[1].split(";")[0])
    assert sent == len(peer.frames) and sent >= N_FRAMES - dropped - len(BLANK) - 1
    assert "jawOpen" in peer.frames[-1] and "tongueOut" in peer.frames[-1]
    assert all(0.0 <= v <= 1.0 for f in peer.frames for v in f.values())
    heads = [a for addr, a in peer.other if addr == "/VMC/Ext/Bone/Pos" and a[0] == "Head"]
    assert heads  # the head's rotation goes out as the relay sends it
    raw, cleaned = io.load(record), io.load(tmp_path / "session.clean.csv")
    assert raw.n_frames == cleaned.n_frames >= sent
    assert (~raw.valid).sum() >= 1  # the black frames: missing rows in the raw recording


def test_camera_frames_go_out_over_live_link(face_video):
    from faceclean.relay import livelink

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.5)
    got = []

    def listen():
        decoder = livelink.Decoder()
        while True:
            try:
                data = sock.recv(65535)
            except (TimeoutError, OSError):
                return
            got.append(decoder.feed(data))

    reader = threading.Thread(target=listen)
    reader.start()
    url = f"livelink://127.0.0.1:{sock.getsockname()[1]}"
    try:
        assert main(["track", "--camera", face_video, "--send", url, "--method", "one-euro"]) == 0
    finally:
        reader.join(5)
        sock.close()
    frames = [f for f in got if f is not None]
    assert len(frames) >= 10
    yaw = np.array([f.pose[0] for f in frames])  # rad, HeadYaw
    assert yaw.max() - yaw.min() > 0.3  # the head turned both ways in the video


def test_live_refuses_what_it_cannot_do(face_video, capsys):
    for argv, words in (
        (["--camera", face_video, "--send", "vmc://127.0.0.1:9", "--ui", "--ui-port", "70000"],
         "0..65535"),  # the page's own refusal (its camera path: tests/ui/test_ui_camera.py)
        (["--camera", "97", "--send", "vmc://127.0.0.1:9"], "camera 97 does not open"),
        (["--camera", face_video, "--send", "ftp://x:1"], "ftp"),
        (["--camera", face_video, "--send", "vmc://127.0.0.1:9", "--method", "gaussian"],
         "offline"),
    ):  # fmt: skip
        assert main(["track", *argv]) == 2
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err, err


def test_a_camera_lost_mid_run_is_one_line_exit_1_and_a_whole_recording(rendered, tmp_path,
                                                                        capsys):  # fmt: skip
    from conftest import write_video

    whole = write_video(tmp_path / "cam.avi", rendered, 30, "MJPG")
    data = Path(whole).read_bytes()
    cut = tmp_path / "unplugged.avi"  # the camera stops delivering half way
    cut.write_bytes(data[: len(data) // 2])
    record = tmp_path / "session.csv"
    with vmc_peer() as peer:
        argv = ["--camera", str(cut), "--send", f"vmc://127.0.0.1:{peer.port}",
                "--record", str(record)]  # fmt: skip
        assert main(["track", *argv]) == 1
    captured = capsys.readouterr()
    lines = [ln for ln in captured.err.splitlines() if ln.startswith("faceclean:")]
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    assert f"camera {cut} stopped delivering frames (the file failed mid-stream" in lines[0]
    assert "plugged in" in lines[0] and f"recording up to then is in {record}" in lines[0]
    raw, cleaned = io.load(record), io.load(tmp_path / "session.clean.csv")
    assert 3 <= raw.n_frames == cleaned.n_frames < N_FRAMES  # written whole, up to the loss
    names = sorted(p.name for p in tmp_path.iterdir())  # no temporaries left
    assert names == ["cam.avi", "session.clean.csv", "session.csv", "unplugged.avi"]


def test_live_says_once_when_two_faces_are_in_view(two_faces, tmp_path, capsys):
    from conftest import write_video

    video = write_video(tmp_path / "two.mp4", two_faces, 30)
    with vmc_peer() as peer:  # live keeps running with two faces: exit 0, not issue 36's 1
        assert main(["track", "--camera", video, "--send", f"vmc://127.0.0.1:{peer.port}"]) == 0
    said = capsys.readouterr().out
    crowd = [ln for ln in said.splitlines() if "faces in view" in ln]
    assert len(crowd) == 1 and "on the left of the picture" in crowd[0], said
