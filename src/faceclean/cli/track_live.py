"""``faceclean track --camera N|FILE --send URL``: the live half of ``track``.

The camera (an OpenCV index, or a video file played at its own pace as a stand-in),
MediaPipe on each newest frame at its capture time, the cleaner (causal only), the head
angles' rotation filter, and one datagram per frame to ``--send`` (VMC or Live Link, the
relay's encoders). Ctrl-C or SIGTERM stops it with exit 0 and a final counters line;
a camera that stops delivering (unplugged) ends it with that said and exit 1; a file's
end is a normal stop. ``--record take.csv`` writes the raw scores to take.csv and what
was sent to take.clean.csv (the relay's recorder). ``--ui`` serves the tuning page on
the loop, the camera's image beside the faces (cli/ui.camera_page, faceclean.ui.camera).

Unplugged (``Camera.lost``): a camera read that fails, no frame for ``video.STALL`` s, or
a stand-in file that fails mid-stream. The recording is written first; the one line
says what stopped and what to do.
"""

from __future__ import annotations

import argparse
import sys

from faceclean.cli import options, stopping
from faceclean.errors import FacecleanError

MIN_STATS, MAX_STATS = 0.001, 86400.0  # s, the --stats period


def run(args: argparse.Namespace) -> int:
    from faceclean.adjust import Adjust, Adjusted
    from faceclean.channels import ARKIT52, POSE
    from faceclean.cli import ui
    from faceclean.cli.relay import build_cleaner, check_record, save_record
    from faceclean.relay import parse
    from faceclean.relay.loop import probe, warm_up
    from faceclean.relay.recorder import Recorder
    from faceclean.trackers.face import FaceTracker, model_path
    from faceclean.trackers.live import Live
    from faceclean.trackers.video import Camera, check_video_file
    from faceclean.ui.live import Tap

    if not args.send:
        raise FacecleanError("--camera needs --send URL (vmc://HOST:PORT or livelink://HOST:PORT)")
    if args.jobs != 1 or args.keep_raw or args.fmt:
        raise FacecleanError("--jobs, --keep-raw and --format are for videos, not --camera")
    if args.stats is not None and not MIN_STATS <= args.stats <= MAX_STATS:
        raise FacecleanError(f"--stats must be between {MIN_STATS:g} and {MAX_STATS:g} s")
    source = camera_source(args.camera)  # an index out of range: refused before any work
    send = parse(args.send, "send")
    script = ui.script(args, args.ui)  # a bad --script fails before the camera opens
    choice = options.choice(args)
    cleaner, what = build_cleaner(choice)  # an offline cleaner is refused
    adjust = (options.calibration(args) or Adjust()).merged(choice.adjust(ARKIT52))
    if not adjust.is_identity:
        cleaner = Adjusted(cleaner, adjust, ARKIT52)
    warm_up(cleaner)
    probe(cleaner)
    pose = choice.build_pose(POSE)
    if isinstance(source, str):  # noted as an input: a --record naming it is refused now
        check_video_file(source)
    recorder = Recorder(args.record) if args.record else None
    check_record(recorder, "the tracking")  # "will replace X": said now, not at the end
    model = model_path(args.tracker_model)
    tap = Tap(recorder) if args.ui else None  # --ui: the page sees every frame (ui/live.py)
    sink = recorder if tap is None else tap
    live = None
    # until the recording is saved: a second signal (``timeout``'s) loses nothing
    with stopping(lambda: live.stop() if live is not None else None):
        with (
            FaceTracker(model, lambda line: print(line, flush=True)) as tracker,
            Camera(source) as camera,
            Live(camera, tracker, cleaner, send, pose=pose, recorder=sink) as live,
            ui.camera_page(args, live, camera, tap, script),
        ):
            print(f"track camera {args.camera} -> {send} ({what}); Ctrl-C stops", flush=True)
            camera.start()
            stats = live.run(args.stats, lambda s: print(f"stats: {s.line()}", flush=True))
        print(f"stopped: {stats.line()}", flush=True)
        if recorder is not None and len(recorder):
            print(save_record(recorder, "raw"), flush=True)
        elif recorder is not None:
            print("recorded nothing: no face was sent, so no file was written", flush=True)
    if stats.send_errors:
        print(f"faceclean: {stats.send_errors} sends refused by {send}", file=sys.stderr)
    if camera.lost is not None and not live.stopped:  # unplugged, stalled, a failed file
        kept = ""
        if recorder is not None and len(recorder):
            kept = f"; the recording up to then is in {args.record}"
        print(f"faceclean: camera {args.camera} stopped delivering frames ({camera.lost}): "
              f"check that it is plugged in and no other program holds it, then run again{kept}",
              file=sys.stderr)  # fmt: skip
        return 1
    return 0


MAX_CAMERA = 99  # OpenCV reads an index of 100 or more as a backend's number plus an index


def camera_source(text: str) -> int | str:
    """``--camera``'s value: a camera index (digits, 0..MAX_CAMERA), else a video path; an
    index out of range is one line (OpenCV failed on one past a C int, and "-1" was
    looked for as a file)."""
    import re

    if not re.fullmatch(r"\s*[+-]?[0-9]+\s*", text):
        return text
    index = int(text)
    if not 0 <= index <= MAX_CAMERA:
        raise FacecleanError(f"--camera {text.strip()}: a camera index is 0 to {MAX_CAMERA} "
                             "(0 is the first camera), or give a video file's path")  # fmt: skip
    return index
