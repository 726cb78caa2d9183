"""The guided calibration's panel in a real headless Chromium, against the real commands:
``relay --ui --script`` fed by ``faceclean replay`` of a face performing a studio's own
short script (an ARKit face with its own levels, late and uneven: tests/test_guided.py's
performer; the live recording lasts the script, so the shipped one's 34 s would be waited
for in real time), a Live Link receiver behind it; and ``faceclean ui`` on a take of the
shipped script, where the take is the performance. Needs Debian's chromium and playwright
(tests/headless.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from headless import browser_missing
from helpers import free_port, interrupt, reaped
from test_guided import SCRIPT, SHORT, arkit_face, performed
from test_ui_page import ENV, Receiver, Tab, start

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.cli import main
from faceclean.guided.script import from_dict

pytest.importorskip("websockets")
pytestmark = pytest.mark.skipif(browser_missing() is not None, reason=str(browser_missing()))
SQUINT = ARKIT52.index("eyeSquintLeft")  # the performer rests at 0.12 on it (arkit_face)


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    """The script performed 0.5 s late at about 1.15 times its pace (31 s at 60 fps): a
    take the live recording (the script's 33.9 s and 3 s more) holds whole even when the
    replay starts a few seconds after the recording."""
    tau, s = performed(late=0.5, speed=1.15, rate=60.0)
    path = tmp_path_factory.mktemp("guided") / "performed.csv"
    io.save(Animation(tau, arkit_face(SCRIPT.weights(s)), ARKIT52), path)
    return path


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """(a studio's short script file, a take of it): 0.5 s late at about 1.15 times its
    pace, 60 fps; the live recording (6.6 s and 3 s more) holds it whole."""
    folder = tmp_path_factory.mktemp("short")
    script = from_dict(SHORT)
    tau, s = performed(late=0.5, speed=1.15, rate=60.0, script=script)
    io.save(Animation(tau, arkit_face(script.weights(s)), ARKIT52), folder / "performed.csv")
    (folder / "short.json").write_text(json.dumps(SHORT))
    return folder / "short.json", folder / "performed.csv"


def replay(take, port: int, loop: bool = False) -> subprocess.Popen:
    argv = [sys.executable, "-m", "faceclean", "replay", str(take), "--send",
            f"vmc://127.0.0.1:{port}", *(["--loop"] if loop else [])]  # fmt: skip
    return subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV)


def squint(receiver: Receiver, first: int, n: int) -> np.ndarray:
    """eyeSquintLeft of ``n`` frames the receiver got from frame ``first`` on (waited for)."""
    while len(receiver.frames) < first + n:
        receiver.arrived.clear()
        if len(receiver.frames) < first + n:
            receiver.arrived.wait(1.0)
    return np.array([v[SQUINT] for _, v in receiver.frames[first : first + n]])


@pytest.mark.slow
@pytest.mark.realtime
def test_the_live_page_prompts_records_fits_applies_undoes_and_saves(browser, short, tmp_path):
    script, take = short
    prompts = len(SHORT["prompts"])
    port, receiver = free_port(), Receiver()
    relay, url = start(["relay", "--listen", f"vmc://127.0.0.1:{port}",
                        "--send", f"livelink://127.0.0.1:{receiver.port}", "--method", "one-euro",
                        "--set", "min_cutoff=30", "--set", "beta=0", "--ui", "--ui-nice", "0",
                        "--script", str(script)], stderr=subprocess.DEVNULL)  # fmt: skip
    with reaped(relay):
        tab = Tab(browser, url)
        rows = tab.js("document.querySelectorAll('#fc-guided-prompts tbody tr').length")
        assert rows == prompts  # every prompt of the studio's script, listed
        tab.page.click("#fc-guided-start")
        tab.until("window.faceclean.guidedPhase === 'recording' || window.faceclean.errors.length")
        first = replay(take, port)  # the person starts once the prompts do
        with reaped(first):
            tab.until("window.faceclean.guided || window.faceclean.errors.length")
            assert tab.js("window.faceclean.errors") == []
            first.wait()
        uncalibrated = squint(receiver, 0, 60)  # the first pass: the face's rest, as it reads
        done = tab.js("window.faceclean.guided")
        shown = tab.js("window.faceclean.guidedShown")
        # each prompt showed, with the seconds it had left, while the server recorded
        assert shown[0].startswith("guided calibration in 3.0 s · first: Relax")
        assert any(s.startswith("Big smile · ") for s in shown)
        assert any(s.startswith("rest · next: Frown") for s in shown)
        assert done["seen"] == prompts and done["problem"] is None, done["problem"]
        assert done["applied"] and done["undo"] and done["tracker"] == "arkit"
        smile = next(p for p in done["prompts"] if p["id"] == "smile")
        assert smile["before"] == pytest.approx(0.5, abs=0.05)  # this face's small smile ...
        assert smile["after"] == pytest.approx(1.0, abs=0.05)  # ... reaches the aim
        assert done["channels"][0]["name"] in ("mouthSmileLeft", "mouthSmileRight")
        assert "prompts seen" in tab.page.inner_text("#fc-calibration")
        state = tab.js("window.faceclean.state.calibration")
        assert (
            len(state["guided"]["seen"]) == prompts and state["guided"]["script"] == "a short one"
        )
        if os.environ.get("FACECLEAN_SCREENSHOTS"):  # docs/ui-guided.png
            tab.page.screenshot(path=os.environ["FACECLEAN_SCREENSHOTS"] + "/ui-guided.png")

        # applied between frames to the running cleaner: the rest now reads 0
        second = replay(take, port, loop=True)
        with reaped(second):
            n = len(receiver.frames)
            calibrated = squint(receiver, n, 60)
            seq = tab.js("window.faceclean.send({type: 'guided', action: 'undo'})")
            tab.until(f"window.faceclean.state.seq >= {seq} || window.faceclean.errors.length")
            assert tab.js("window.faceclean.state.calibration") is None
            tab.until("window.faceclean.guided && !window.faceclean.guided.applied")
            n = len(receiver.frames)
            undone = squint(receiver, n + 5, 60)
            assert tab.page.is_visible("#fc-guided-apply")  # ... and it can be put back
            tab.page.fill("#fc-guided-path", str(tmp_path / "guided.json"))
            tab.note_after("#fc-guided-save", "saved guided calibration")
        assert tab.errors() == []
        tab.page.close()
        out, err = interrupt(relay)
    receiver.close()
    assert uncalibrated.min() > 0.06 and undone.min() > 0.06, (uncalibrated.min(), undone.min())
    assert calibrated.min() < 0.02 and np.median(calibrated) < 0.03, calibrated
    assert (
        "guided calibration (live take" in out
        and f"{prompts} of {prompts} prompts seen; applied" in out
    )
    saved = json.loads((tmp_path / "guided.json").read_text())
    assert saved["calibration"]["guided"]["not_seen"] == []
    assert main(["clean", str(take), "-o", str(tmp_path / "out.csv"),
                 "--calibration", str(tmp_path / "guided.json")]) == 0  # fmt: skip


@pytest.mark.parametrize("tracker", ["arkit", "mediapipe"])
def test_the_offline_page_fits_the_take_as_calibrate_guided_does(browser, take, tmp_path,
                                                                 tracker):  # fmt: skip
    """ARKit: levels before the cleaner; MediaPipe: the correction after its shipped map."""
    proc, url = start(["ui", str(take), "--tracker", tracker])
    with reaped(proc):
        tab = Tab(browser, url)
        assert tab.page.inner_text("#fc-guided-start") == "fit this take"
        tab.page.click("#fc-guided-start")
        tab.until("window.faceclean.guided || window.faceclean.errors.length")
        done = tab.js("window.faceclean.guided")
        assert done["applied"] and done["tracker"] == tracker and done["channels"]
        assert done["seen"] == len(SCRIPT.prompts), done["problem"]
        kind = "neutral" if tracker == "arkit" else "offset"  # what the table shows
        assert all(kind in c for c in done["channels"])
        shown = tab.page.inner_text("#fc-guided-channels")
        assert "gain" in shown
        tab.page.fill("#fc-guided-path", str(tmp_path / "page.json"))
        tab.note_after("#fc-guided-save", "saved guided calibration")
        assert f"--calibration {tmp_path / 'page.json'}" in tab.js("window.faceclean.state.command")
        assert tab.errors() == []
        tab.page.close()
        interrupt(proc)
    cli_json = str(tmp_path / "cli.json")
    assert main(["calibrate", "--guided", str(take), "-o", cli_json, "--tracker", tracker]) == 0
    page = json.loads((tmp_path / "page.json").read_text())
    cli = json.loads((tmp_path / "cli.json").read_text())
    assert page == cli  # the same fit, the same file
    # the brows read as their own rise (this face's read as they are) are said on the page
    own = cli.get("adaptation", {}).get("own", [])
    assert bool(own) == (tracker == "mediapipe")
    assert shown.count("read as its own rise alone") == len(own)


def test_a_take_that_ignored_the_script_is_shown_and_applied_only_when_asked(browser, take):
    still = io.load(take)
    keep = still.times < 2.0  # the neutral hold, repeated: a face that held still
    reps = int(np.ceil(still.n_frames / keep.sum()))
    values = np.tile(still.values[keep], (reps, 1))[: still.n_frames]
    path = take.parent / "still.csv"
    io.save(Animation(still.times, values, still.names), path)
    proc, url = start(["ui", str(path), "--method", "one-euro"])
    with reaped(proc):
        tab = Tab(browser, url)
        tab.page.click("#fc-guided-start")
        tab.until("window.faceclean.guided || window.faceclean.errors.length")
        done = tab.js("window.faceclean.guided")
        assert not done["applied"] and "did not follow the script" in done["problem"]
        assert done["problem"].endswith("apply anyway fits its neutral holds alone")
        assert tab.js("window.faceclean.state.calibration") is None
        assert "did not follow the script" in tab.page.inner_text("#fc-guided-summary")
        tab.page.click("#fc-guided-apply")  # --partial's rule: only when asked
        tab.until("window.faceclean.guided.applied || window.faceclean.errors.length")
        assert tab.js("window.faceclean.state.calibration.guided.follows") is False
        assert tab.errors() == []
        tab.page.close()
        interrupt(proc)
