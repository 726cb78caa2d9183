"""trackers/video.py: a video's own times (24/30/60 fps, variable), bad files, the camera."""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import VFR_TIMES, write_vfr, write_video

from faceclean.errors import FacecleanError
from faceclean.io import paths
from faceclean.trackers.video import Camera, Video

cv2 = pytest.importorskip("cv2")


def _frames(n: int, size: int = 64) -> np.ndarray:
    """(n, size, size, 3) RGB, each frame a different grey: order can be checked."""
    return (
        np.repeat(np.arange(n, dtype=np.uint8)[:, None, None, None] * 8, size, 1)
        .repeat(size, 2)
        .repeat(3, 3)
    )


@pytest.mark.parametrize(
    ("name", "fourcc", "fps"),
    [("a.mp4", "mp4v", 30.0), ("a.avi", "MJPG", 24.0), ("a.webm", "VP80", 60.0)],
)
def test_constant_rate_times_are_the_frames_own(tmp_path, name, fourcc, fps):
    path = write_video(tmp_path / name, _frames(12), fps, fourcc)
    with Video(path) as video:
        got = list(video)
    times = np.array([t for _, t in got])
    np.testing.assert_allclose(times, np.arange(12) / fps, atol=1.5e-3)  # ms rounding
    greys = [int(f[..., 0].mean()) for f, _ in got]
    assert greys == sorted(greys) and greys[-1] > greys[0]  # in order, none repeated
    assert got[0][0].shape == (64, 64, 3) and got[0][0].dtype == np.uint8


def test_variable_frame_rate_keeps_each_frames_time(tmp_path):
    path = write_vfr(tmp_path / "vfr.mp4", _frames(len(VFR_TIMES)), VFR_TIMES)
    with Video(path) as video:
        times = np.array([t for _, t in video])
    np.testing.assert_allclose(times, VFR_TIMES, atol=1e-3)


def test_not_a_video_missing_folder_and_truncated_are_one_line(tmp_path):
    text = tmp_path / "notes.mp4"
    text.write_text("not a video\n" * 50)
    for bad, words in ((text, "not a video"), (tmp_path / "gone.mp4", "no such file"),
                       (tmp_path, "not a regular file")):  # fmt: skip
        with pytest.raises(FacecleanError, match=words) as e, Video(bad) as v:
            list(v)
        assert "\n" not in str(e.value)
    whole = write_video(tmp_path / "whole.avi", _frames(40), 30, "MJPG")
    data = Path(whole).read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(FacecleanError, match="truncated|not a video"), Video(cut) as v:
        list(v)


def test_a_video_read_is_protected_from_the_commands_outputs(tmp_path):
    path = write_video(tmp_path / "a.mp4", _frames(3), 30)
    with paths.command():
        Video(path).close()
        with pytest.raises(FacecleanError, match="reads"):
            paths.target(path)


def test_a_file_stands_in_for_a_camera_at_its_own_pace(tmp_path):
    path = write_video(tmp_path / "cam.mp4", _frames(15), 30)
    taken = []
    with Camera(path) as cam:
        cam.start()
        while not (cam.ended and len(taken) >= cam.captured - cam.dropped):
            got = cam.latest(timeout=0.5)
            if got is not None:
                taken.append(got[1])
    assert cam.captured == 15
    assert len(taken) + cam.dropped == 15
    span = taken[-1] - taken[0]  # s, stamped at capture: the file's 14/30 s, played
    assert 0.3 < span < 1.5


def test_frames_not_taken_in_time_are_counted_as_dropped(tmp_path):
    path = write_video(tmp_path / "cam.mp4", _frames(20), 60)
    taken = 0
    with Camera(path) as cam:
        cam.start()
        while not cam.ended or cam.latest(timeout=0) is not None:
            if cam.latest(timeout=0.5) is not None:
                taken += 1
            time.sleep(0.05)  # a slow consumer: the camera moves on meanwhile
    assert cam.captured == 20
    assert cam.dropped >= 10  # at 60 fps about 3 frames go by per 50 ms
    assert cam.dropped + taken <= 20


def test_a_camera_index_that_does_not_open_is_one_line():
    with pytest.raises(FacecleanError, match="camera 97 does not open"):
        Camera(97)


def test_a_source_that_goes_quiet_is_lost_not_ended(tmp_path):
    # frames for 0.2 s, then nothing for 3 s (then more): a camera unplugged mid-run
    times = np.array([0, 33, 66, 100, 133, 166, 200, 3200, 3233]) / 1000.0
    path = write_vfr(tmp_path / "gap.mp4", _frames(len(times)), times)
    with Camera(path, stall=0.4) as cam:
        cam.start()
        while not cam.ended:
            cam.latest(timeout=0.1)
    assert cam.captured == 7  # the frames before the gap, none after
    assert cam.lost == "no frame for 0.4 s"


def test_a_stand_in_that_fails_mid_stream_is_lost_and_its_end_is_not(tmp_path):
    whole = write_video(tmp_path / "whole.avi", _frames(40), 120, "MJPG")
    data = Path(whole).read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: len(data) // 2])
    for path, lost in ((cut, "failed mid-stream: .*truncated"), (whole, None)):
        with Camera(path) as cam:
            cam.start()
            while not cam.ended:
                cam.latest(timeout=0.1)
        assert cam.captured >= 5  # it played up to the cut
        if lost is None:
            assert cam.lost is None and cam.captured == 40  # a file's end: a normal end
        else:
            assert re.search(lost, cam.lost) and "\n" not in cam.lost
