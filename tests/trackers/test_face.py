"""trackers/face.py: MediaPipe on real video files: lost faces, the video's times, the head."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import BLANK, N_FRAMES, VFR_TIMES, YAW, yaw_of

from faceclean.trackers.face import HEAD
from faceclean.trackers.mediapipe import head_angles
from faceclean.trackers.signature import judge


def _renderer_rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """The renderer's R = Ry Rx Rz (deg), written out here: MediaPipe's frame (x: the
    subject's left as the camera sees it, y up, z out of the face)."""
    y, x, z = np.radians([yaw, pitch, roll])
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    return ry @ rx @ rz


@pytest.mark.parametrize("ypr", [(20, 0, 0), (0, 15, 0), (0, 0, 10), (25, -10, 5)])
def test_head_angles_are_live_links_the_x_mirror_of_mediapipes(ypr):
    m = np.eye(4)
    m[:3, :3] = 1.7 * _renderer_rotation(*ypr)  # a scale in the matrix is dropped
    got = np.degrees(head_angles(m))
    # Live Link: +yaw turns to the subject's right, +pitch down, roll mirrored too
    np.testing.assert_allclose(got, [-ypr[0], ypr[1], -ypr[2]], atol=1e-9)


def test_a_rendered_video_tracks_on_its_times_with_lost_faces_missing(face_video):
    from faceclean.trackers.face import track_video

    seen = []
    anim = track_video(face_video, progress=lambda done, total: seen.append((done, total)))
    assert anim.n_frames == N_FRAMES and len(anim.names) == 51
    assert "tongueOut" not in anim.names
    np.testing.assert_allclose(anim.times, np.arange(N_FRAMES) / 30.0, atol=1.5e-3)
    lost = np.flatnonzero(~np.isfinite(anim.values).any(axis=1))
    assert tuple(lost) == BLANK  # no face: missing rows, exactly there, never guessed
    assert np.isnan(anim.meta["pose"][list(BLANK)]).all()
    assert anim.meta["pose_names"] == HEAD
    assert seen[-1] == (N_FRAMES, N_FRAMES)  # progress: done, the container's count
    yaw = np.degrees(anim.meta["pose"][:, 0])
    left = [i for i in range(N_FRAMES) if yaw_of(i) == YAW]
    right = [i for i in range(N_FRAMES) if yaw_of(i) == -YAW and i not in BLANK]
    # turned to the subject's left in the render: negative Live Link yaw, and back
    assert np.median(yaw[left]) < -0.5 * YAW
    assert np.median(yaw[right]) > 0.5 * YAW
    jaw = anim.values[:, anim.names.index("jawOpen")]
    assert np.nanmax(jaw) - np.nanmin(jaw) > 0.1  # the expression is tracked
    assert judge(anim.values, anim.names) is None  # our own raw output passes the check


def test_a_variable_frame_rate_video_keeps_its_times(vfr_video):
    from faceclean.trackers.face import track_video

    anim = track_video(vfr_video)
    np.testing.assert_allclose(anim.times, VFR_TIMES - VFR_TIMES[0], atol=1e-3)
    assert np.isfinite(anim.values).any(axis=1).sum() >= len(VFR_TIMES) - 2


def test_a_video_without_a_face_is_refused(rendered, tmp_path):
    from conftest import write_video

    from faceclean.errors import FacecleanError
    from faceclean.trackers.face import track_video

    blank = write_video(tmp_path / "blank.mp4", rendered[:5], 30, blank=range(5))
    with pytest.raises(FacecleanError, match="no face found in any of its 5 frames"):
        track_video(blank)


def _face(cx: float, cy: float, size: float) -> np.ndarray:
    """(4, 2) px: the corners of a face box of ``size`` px centred on (cx, cy)."""
    h = size / 2
    return np.array([[cx - h, cy - h], [cx + h, cy - h], [cx - h, cy + h], [cx + h, cy + h]])


def test_follow_takes_the_largest_first_then_the_nearest_and_says_so_once():
    from faceclean.trackers.face import Follow

    said: list[str] = []
    follow = Follow(said.append)
    assert follow.choose([_face(500, 200, 80), _face(150, 200, 120)], 0.5, 640) == 1
    assert follow.crowd.startswith("2 faces in view at 0.50 s: tracking the largest, on the left")
    assert said == [follow.crowd]  # given to on_crowd once, when first said
    first = follow.crowd
    # the other face grows larger and the followed one moves a little: still the same one
    assert follow.choose([_face(170, 210, 118), _face(480, 200, 300)], 0.6, 640) == 0
    assert follow.choose([_face(480, 200, 300)], 0.7, 640) == 0  # alone in view: followed
    assert said == [first]
    follow = Follow()
    follow.choose([_face(150, 200, 120)], 0.0, 640)  # one face: nothing to say
    assert follow.crowd is None
    assert follow.choose([_face(600, 50, 200), _face(160, 205, 100)], 0.1, 640) == 1
    assert "tracking the one followed so far" in follow.crowd
    assert follow.crowd != first


def test_the_track_tracker_is_the_one_tracker_interface(face_video, rendered):
    """FaceTracker is a tracking.Tracker (MediaPipe's one implementation, with the head's
    angles): a whole video tracked is that interface's scores, frame by frame."""
    from faceclean import tracking
    from faceclean.trackers.face import FaceTracker, track_video
    from faceclean.trackers.mediapipe import NAMES
    from faceclean.trackers.video import Video

    with FaceTracker() as tracker:
        assert isinstance(tracker, tracking.Tracker) and tracker.names == NAMES
        assert tracker.name.startswith("mediapipe ")
        reading = tracker.read(rendered[0], 0.0)
        assert reading.landmarks.shape == (478, 3) and reading.pose.shape == (3,)
        assert np.degrees(reading.pose[0]) < -0.5 * YAW  # frame 0 turned: negative yaw
        assert tracker.read(np.zeros_like(rendered[0]), 1 / 30) is None  # no face
    with Video(face_video) as video, FaceTracker() as tracker:
        scores = tracking.scores(tracker, video)
    np.testing.assert_array_equal(scores, track_video(face_video).values)
