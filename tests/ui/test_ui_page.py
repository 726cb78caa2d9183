"""The tuning page in a real headless Chromium against the real commands: ``faceclean ui``
on a shared take, and ``faceclean relay --ui`` fed by ``faceclean replay`` of one, with
a real receiver. Needs Debian's chromium and playwright (tests/headless.py)."""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest
from headless import BROWSER_ARGS, CHROMIUM, browser_missing, until
from helpers import REPO, first_take, interrupt, reaped

from faceclean import io
from faceclean.cli import main

pytest.importorskip("websockets")
pytestmark = pytest.mark.skipif(browser_missing() is not None, reason=str(browser_missing()))
ENV = dict(os.environ, PYTHONPATH=str(REPO / "src"))
URL = re.compile(r"tuning page: (http://\S+)")


def start(args: list[str], stderr=subprocess.PIPE) -> tuple[subprocess.Popen, str]:
    """A faceclean command that serves the page, and the URL it printed."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "faceclean", *args, "--no-browser"],
        stdout=subprocess.PIPE,
        stderr=stderr,
        text=True,
        env=ENV,
    )
    for line in proc.stdout:
        found = URL.search(line)
        if found:
            return proc, found[1]
    proc.kill()
    raise AssertionError(f"no URL printed: {proc.stderr.read()[-2000:]}")


class Held:
    """The live channel through Playwright: the server's messages reach the page as they
    come, or, while ``on``, wait until ``release()`` (the page's go out as they come)."""

    def __init__(self) -> None:
        self.on = False
        self.waiting: list[str | bytes] = []
        self.page_end = None

    def route(self, page) -> None:
        page.route_web_socket(re.compile(r"/live"), self._connect)

    def _connect(self, ws) -> None:
        self.page_end = ws
        ws.connect_to_server().on_message(self._down)

    def _down(self, message: str | bytes) -> None:
        if self.on:
            self.waiting.append(message)
        else:
            self.page_end.send(message)

    def release(self) -> None:
        self.on = False
        for message in self.waiting:
            self.page_end.send(message)
        self.waiting.clear()


class Tab:
    """One page: console errors kept, waits frame by frame on a JS condition."""

    def __init__(self, browser, url: str, held: Held | None = None) -> None:
        self.messages: list[tuple[str, str]] = []
        self.page = browser.new_page(viewport={"width": 1400, "height": 1000})
        if held is not None:
            held.route(self.page)
        self.page.on("console", lambda m: self.messages.append((m.type, m.text)))
        self.page.on("pageerror", lambda e: self.messages.append(("pageerror", str(e))))
        self.page.goto(url)
        self.until("window.faceclean && window.faceclean.ready && window.faceclean.faceReady")

    def until(self, condition: str, seconds: float = 120.0) -> None:
        until(self.page, condition, seconds)

    def js(self, expression: str):
        return self.page.evaluate(expression)

    def slide(self, key: str, fraction: float) -> int:
        """Click the slider of ``key`` at ``fraction`` of its width, as a user does; the
        sequence number of the settings message it sent."""
        box = self.page.locator(f"#fc-{key}").bounding_box()
        before = self.js("window.faceclean.setSeq")
        self.page.mouse.click(box["x"] + fraction * box["width"], box["y"] + box["height"] / 2)
        self.until(f"window.faceclean.setSeq > {before}")
        return self.js("window.faceclean.setSeq")

    def settled(self, seq: int) -> None:
        """Until the state and the whole cleaned take answer message ``seq``."""
        self.until(
            f"window.faceclean.state.seq >= {seq} && window.faceclean.fullSeq >= {seq}"
            f" || window.faceclean.errors.length"
        )
        assert self.js("window.faceclean.errors") == []

    def note_after(self, button: str, text: str) -> None:
        n = self.js("window.faceclean.notes.length")
        self.page.click(button)
        self.until(f"window.faceclean.notes.length > {n} || window.faceclean.errors.length")
        assert self.js("window.faceclean.errors") == []
        assert text in self.js("window.faceclean.notes.at(-1)")

    def errors(self) -> list[tuple[str, str]]:
        return [m for m in self.messages if m[0] in ("error", "pageerror")]


def _cleaned(tab: Tab, n: int) -> np.ndarray:
    return np.array(tab.js("Array.from(window.faceclean.cleaned)"), np.float64).reshape(n, 52)


def test_offline_page_tunes_calibrates_and_saves_what_clean_reproduces(browser, tmp_path):
    take = first_take("jmtechart")
    anim = io.load(take)
    proc, url = start(["ui", str(take), "--method", "one-euro"])
    with reaped(proc):
        tab = Tab(browser, url)
        tab.settled(0)
        assert tab.js("window.faceclean.mode") == "offline"
        before = _cleaned(tab, anim.n_frames)
        tab.page.select_option("#fc-scope", "eyes")
        tab.settled(tab.slide("min_cutoff", 0.05))  # eyes: heavy smoothing
        tab.page.select_option("#fc-scope", "jawOpen")
        tab.settled(tab.slide("gain", 0.4))  # jawOpen.gain=1.6
        items = tab.js("window.faceclean.state.items")
        assert [i.split("=")[0] for i in items] == ["eyes.min_cutoff", "jawOpen.gain"]
        tab.page.fill("#fc-hold", "1")
        n = tab.js("window.faceclean.sentSeq")
        tab.page.click("#fc-calibrate")
        tab.settled(n + 1)
        facts = tab.js("window.faceclean.state.calibration")
        assert facts["take"] == take.name and facts["frames"] == anim.valid.sum()
        page = _cleaned(tab, anim.n_frames)
        tab.page.fill("#fc-path", str(tmp_path / "preset.json"))
        tab.note_after("#fc-save-preset", "saved preset")
        tab.page.fill("#fc-path", str(tmp_path / "levels.json"))
        tab.note_after("#fc-save-levels", "saved levels")
        assert "replacing" not in tab.js("window.faceclean.notes.at(-1)")
        tab.note_after("#fc-save-levels", "saved levels")  # again: the file is there now
        assert tab.js("window.faceclean.notes.at(-1)").endswith(
            "(replacing the file that was there)"
        )
        assert tab.errors() == []
        tab.page.screenshot(path=str(tmp_path / "offline.png"))
        if os.environ.get("FACECLEAN_SCREENSHOTS"):  # docs/ui-offline.png
            tab.page.screenshot(path=os.environ["FACECLEAN_SCREENSHOTS"] + "/ui-offline.png")
        tab.page.close()
        interrupt(proc)
    assert np.nanmax(np.abs(page - before)) > 0.05  # the page's changes show
    files = ["--preset", str(tmp_path / "preset.json")]
    files += ["--calibration", str(tmp_path / "levels.json")]
    assert main(["clean", str(take), "-o", str(tmp_path / "out.csv"), *files]) == 0
    out, present = io.load(tmp_path / "out.csv").arkit()
    assert present.sum() == anim.arkit()[1].sum()
    gap = np.abs(out[:, present] - page[:, present])
    assert np.nanmax(gap) < 1e-6  # the files give what the page showed
    assert np.array_equal(np.isnan(out[:, present]), np.isnan(page[:, present]))


def test_a_new_value_moves_its_slider_and_only_a_new_cleaner_rebuilds_the_panel(browser):
    """A state that keeps the cleaner's keys moves the sliders in place (no rebuilt panel:
    on software GL a layout delays the cleaned window, docs/BENCHMARKS.md); a new cleaner
    or scope builds the controls for its keys."""
    proc, url = start(["ui", str(first_take("jmtechart")), "--method", "one-euro"])
    with reaped(proc):
        tab = Tab(browser, url)
        tab.settled(0)
        tab.js("document.querySelector('#fc-min_cutoff').dataset.mark = 'kept'")
        tab.page.fill("#fc-items", "min_cutoff=2\nbeta=0.5")  # typed, as a user does
        n = tab.js("window.faceclean.sentSeq")
        tab.page.click("#fc-apply")
        tab.settled(n + 1)
        shown = tab.js("[...document.querySelectorAll('#fc-smoothing .slider span')]"
                       ".map((e) => e.textContent)")  # fmt: skip
        assert tab.js("document.querySelector('#fc-min_cutoff').dataset.mark") == "kept"
        assert shown[:2] == ["2", "0.5"]  # min_cutoff, beta: moved to the state's values
        assert tab.js("window.faceclean.state.items") == ["min_cutoff=2", "beta=0.5"]
        tab.page.select_option("#fc-scope", "eyes")  # another scope: its own controls
        assert tab.js("document.querySelector('#fc-min_cutoff').dataset.mark") is None
        tab.page.fill("#fc-words", "ema")
        n = tab.js("window.faceclean.sentSeq")
        tab.page.dispatch_event("#fc-words", "change")
        tab.settled(n + 1)
        assert tab.js("window.faceclean.state.method") == "ema"
        assert tab.js("document.querySelector('#fc-min_cutoff')") is None  # EMA has no such key
        assert tab.errors() == []
        tab.page.close()
        interrupt(proc)


def test_the_curves_window_and_playhead_follow_their_controls(browser):
    """The curve pickers add and remove plot rows; the window pages the take (a new page
    asks the server for its part); the scrubber, a click on a curve, play and Space move
    the playhead; clamp and off are the scope's --set items."""
    take = first_take("jmtechart")
    anim = io.load(take)
    duration = float(anim.times[-1] - anim.times[0])  # s
    proc, url = start(["ui", str(take), "--method", "one-euro"])
    with reaped(proc):
        tab = Tab(browser, url)
        tab.settled(0)
        rows = "[...document.querySelectorAll('#fc-curves .name')].map((e) => e.firstChild.data)"
        assert tab.js(rows) == ["jawOpen", "eyeBlinkLeft", "mouthSmileLeft", "browInnerUp"]
        tab.page.select_option("#fc-group", "-")  # none
        assert tab.js(rows) == []
        tab.page.select_option("#fc-group", "jaw")
        tab.page.select_option("#fc-channel", "cheekPuff")
        tab.page.click("#fc-curves .plot:first-child .name button")  # x: jawForward goes
        assert tab.js(rows) == ["jawLeft", "jawRight", "jawOpen", "cheekPuff"]
        assert tab.js("document.querySelector('#fc-group').value") == ""  # back to its prompt

        assert duration > 4.5  # two pages of 4 s
        tab.page.select_option("#fc-span", "4")
        sent = tab.js("window.faceclean.sentSeq")
        tab.page.fill("#fc-scrub", "2000")
        tab.page.dispatch_event("#fc-scrub", "input")
        assert abs(tab.js("window.faceclean.time") - 0.2 * duration) < 1e-3
        assert tab.js("window.faceclean.sentSeq") == sent  # the same page: nothing asked
        tab.page.fill("#fc-scrub", "9000")
        tab.page.dispatch_event("#fc-scrub", "input")
        assert tab.js("window.faceclean.sentSeq") == sent + 1  # the second page's part
        assert tab.page.inner_text("#fc-time") == f"{0.9 * duration:.2f} / {duration:.2f} s"
        box = tab.page.locator("#fc-curves canvas").first.bounding_box()
        tab.page.mouse.click(box["x"] + 0.25 * box["width"], box["y"] + box["height"] / 2)
        assert abs(tab.js("window.faceclean.time") - 5.0) < 0.05  # 4 s + a quarter of 4 s
        tab.page.click("#fc-play")
        assert tab.page.inner_text("#fc-play") == "❚❚ pause"
        tab.until("window.faceclean.time < 4.9")  # played on past the end: from the start
        tab.page.click("#fc-play")
        assert tab.page.inner_text("#fc-play") == "▶ play"
        tab.js("document.activeElement.blur()")
        tab.page.keyboard.press("Space")
        assert tab.page.inner_text("#fc-play") == "❚❚ pause"
        tab.page.keyboard.press("Space")
        assert tab.page.inner_text("#fc-play") == "▶ play"

        tab.page.select_option("#fc-scope", "jawOpen")
        tab.page.fill("#fc-clamp", "0,0.8")
        tab.page.press("#fc-clamp", "Tab")  # its change, as a user's leaving it
        tab.settled(tab.js("window.faceclean.setSeq"))
        tab.page.check("#fc-off")
        tab.settled(tab.js("window.faceclean.setSeq"))
        assert tab.js("window.faceclean.state.items") == ["jawOpen.clamp=0,0.8", "jawOpen.off"]
        assert tab.page.input_value("#fc-items") == "jawOpen.clamp=0,0.8\njawOpen.off"
        assert tab.errors() == []
        tab.page.close()
        interrupt(proc)


def test_off_clicked_while_the_clamp_is_on_its_way_is_kept(browser, tmp_path):
    """Type a clamp value and click off at once: leaving the box sends the clamp, and the
    click comes before the server has answered it (its answer held back until then, so
    always). The newest intent wins: both items stay, on the page, in what the server
    holds (a new page's state) and in a saved preset (the items it keeps as --set)."""
    take = first_take("jmtechart")
    proc, url = start(["ui", str(take), "--method", "one-euro"])
    with reaped(proc):
        held = Held()
        tab = Tab(browser, url, held)
        tab.settled(0)
        tab.page.select_option("#fc-scope", "jawOpen")
        tab.page.fill("#fc-clamp", "0,0.8")
        before = tab.js("window.faceclean.setSeq")
        held.on = True
        tab.page.click("#fc-off")  # the clamp box's change, then the click
        clamp = tab.js("window.faceclean.setSeq")
        assert clamp > before and tab.js("window.faceclean.state.seq") < clamp  # unanswered
        assert tab.page.is_checked("#fc-off")
        held.release()  # the answer to the clamp alone, after the click
        tab.until(
            "window.faceclean.state.seq >= window.faceclean.setSeq"
            " && window.faceclean.fullSeq >= window.faceclean.setSeq"
            " || window.faceclean.errors.length"
        )
        assert tab.js("window.faceclean.errors") == []
        both = ["jawOpen.clamp=0,0.8", "jawOpen.off"]
        assert tab.js("window.faceclean.state.items") == both
        assert tab.page.is_checked("#fc-off")
        assert tab.page.input_value("#fc-clamp") == "0,0.8"
        assert tab.page.input_value("#fc-items") == "\n".join(both)
        tab.page.fill("#fc-path", str(tmp_path / "preset.json"))
        tab.note_after("#fc-save-preset", "saved preset")
        assert tab.js("window.faceclean.notes.at(-1)").endswith(f"keep as --set: {' '.join(both)})")
        assert (tmp_path / "preset.json").is_file()
        fresh = Tab(browser, url)  # what the server holds, as a new page is told it
        assert fresh.js("window.faceclean.state.items") == both
        fresh.page.select_option("#fc-scope", "jawOpen")
        assert fresh.page.is_checked("#fc-off")
        assert tab.errors() == [] and fresh.errors() == []
        fresh.page.close()

        # a clamp the server refuses, then off unticked at once: the refusal takes back
        # the clamp alone, and the untick goes after it
        tab.page.fill("#fc-clamp", "low,high")
        held.on = True
        tab.page.click("#fc-off")
        assert tab.js("window.faceclean.state.seq") < tab.js("window.faceclean.setSeq")
        held.release()
        tab.until(
            "window.faceclean.errors.length"
            " && window.faceclean.state.seq >= window.faceclean.setSeq"
        )
        assert "clamp" in tab.js("window.faceclean.errors.at(-1)")
        assert tab.js("window.faceclean.state.items") == ["jawOpen.clamp=0,0.8"]
        assert not tab.page.is_checked("#fc-off")
        assert tab.page.input_value("#fc-clamp") == "0,0.8"
        tab.page.close()
        interrupt(proc)


class Receiver:
    """A Live Link UDP receiver on loopback: every frame the relay sends, in order."""

    def __init__(self) -> None:
        import socket
        import threading

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.frames: list[tuple[float, np.ndarray]] = []  # (sender time s, (52,) weights)
        self.arrived = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from faceclean.relay import livelink

        while not self._stop.is_set():
            try:
                data = self.sock.recv(65535)
            except TimeoutError:
                continue
            f = livelink.decode(data)
            self.frames.append((float(f.t), np.asarray(f.values[:52], np.float64)))
            self.arrived.set()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.sock.close()


@pytest.fixture(scope="module")
def live(browser, tmp_path_factory):
    """``relay --ui`` (one-euro, light smoothing) fed by ``replay`` of a shared take, a
    Live Link receiver behind it, the page open: (tab, receiver, take frames, folder)."""
    from helpers import free_port

    from faceclean.relay.replay import load_frames

    folder = tmp_path_factory.mktemp("live")
    take = first_take("neurosync")
    port, receiver = free_port(), Receiver()
    relay, url = start(["relay", "--listen", f"vmc://127.0.0.1:{port}",
                        "--send", f"livelink://127.0.0.1:{receiver.port}", "--method", "one-euro",
                        "--set", "min_cutoff=30", "--set", "beta=0", "--ui",
                        "--ui-nice", "0",  # this module's browser keeps its weight
                        "--record", str(folder / "session.csv")],
                       stderr=subprocess.DEVNULL)  # fmt: skip
    replay = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "faceclean",
            "replay",
            str(take),
            "--loop",  # a pass lasts 50 s: the tests may take longer
            "--send",
            f"vmc://127.0.0.1:{port}",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=ENV,
    )
    with reaped(relay), reaped(replay):
        while not receiver.frames:  # the stream is on before the page opens
            assert replay.poll() is None and relay.poll() is None
            receiver.arrived.wait(0.1)
        tab = Tab(browser, url)
        yield tab, receiver, load_frames(take), folder, url
        tab.page.close()
        replay.kill()
        out, err = interrupt(relay)
        assert "stopped:" in out and "recorded" in out, err
    receiver.close()


def test_live_page_shows_the_stream_as_it_comes(live):
    tab, receiver, *_ = live
    tab.until("window.faceclean.frames > 0 && window.faceclean.stats")
    # the page shows the stream as it comes (no timed assertion here: the time from the
    # live channel's opening to its first frames is measured in benchmarks/ui_latency.py)
    assert tab.js("window.faceclean.firstFrameMs") >= tab.js("window.faceclean.openMs")
    tab.until(f"window.faceclean.frames > {tab.js('window.faceclean.frames') + 30}")
    stats = tab.js("window.faceclean.stats")
    assert stats["frames_out"] > 0 and stats["sender"].startswith("127.0.0.1:")
    assert "sender 127.0.0.1:" in tab.page.inner_text("#fc-status")
    assert tab.errors() == []
    if os.environ.get("FACECLEAN_SCREENSHOTS"):  # docs/ui-live.png
        tab.until(f"window.faceclean.frames > {tab.js('window.faceclean.frames') + 240}")
        tab.page.screenshot(path=os.environ["FACECLEAN_SCREENSHOTS"] + "/ui-live.png")


def test_on_software_gl_the_live_view_draws_lighter(live):
    """SwiftShader (this browser's WebGL) is detected, and the live view's draws are capped
    (faces 8 a second, curves 15) while frames arrive at 60: it leaves the CPU to the relay."""
    tab, *_ = live
    tab.until("window.faceclean.faceDraws > 0")
    assert tab.js("window.faceclean.softwareGL") is True
    probe = "[performance.now(), faceclean.faceDraws, faceclean.curveDraws, faceclean.frames]"
    t0, faces0, curves0, frames0 = tab.js(probe)
    tab.until(f"window.faceclean.frames > {frames0 + 120}")
    t1, faces1, curves1, frames1 = tab.js(probe)
    seconds = (t1 - t0) / 1e3
    assert faces1 > faces0 and curves1 > curves0  # the view moves
    assert faces1 - faces0 <= 8 * seconds + 1 and curves1 - curves0 <= 15 * seconds + 1
    assert frames1 - frames0 > faces1 - faces0  # fewer draws than frames


def _sent(take_frames, t: float):
    """The take's frame that ``replay --loop`` sent at sender time t (s): a pass lasts
    the take plus one median frame period."""
    times = np.array([f.t for f in take_frames])
    cycle = times[-1] - times[0] + np.median(np.diff(times))
    return take_frames[int(np.argmin(np.abs(times - (t % cycle))))]


def _roughness(frames) -> float:
    """Mean |y[n] - y[n-1]| over received frames and channels."""
    y = np.array([v for _, v in frames])
    return float(np.nanmean(np.abs(np.diff(y, axis=0))))


@pytest.mark.slow
def test_moving_a_smoothing_slider_changes_what_the_receiver_gets(live):
    tab, receiver, take_frames, *_ = live
    # 600 received frames (10 s) of the light stream first, counted since the relay's
    # start: a shorter window may fall on a still stretch of the take (a 60-frame
    # window's roughness ranges 3e-5..2e-3 over the take)
    tab.until("window.faceclean.frames > 30")
    while len(receiver.frames) < 600:
        receiver.arrived.clear()  # set again by the next frame received
        if len(receiver.frames) < 600:
            receiver.arrived.wait(1.0)
    before = len(receiver.frames)
    seq = tab.slide("min_cutoff", 0.0)  # 0.01 Hz: the heaviest smoothing
    tab.until(f"window.faceclean.state.seq >= {seq} || window.faceclean.errors.length")
    assert tab.js("window.faceclean.errors") == []
    assert tab.js("window.faceclean.state.items")[-1] == "min_cutoff=0.01"
    swapped = len(receiver.frames)
    tab.until(f"window.faceclean.frames > {tab.js('window.faceclean.frames') + 60}")
    light = _roughness(receiver.frames[max(0, before - 600) : before])
    heavy = _roughness(receiver.frames[swapped + 5 :])
    # mean |change| from one received frame to the next, weight units: the light filter
    # passes the take's motion, the heaviest one all but holds (independent of timing,
    # unlike a match by send time, which a loaded machine blurs)
    assert light > 1e-4 and heavy < light / 5, (light, heavy)


def test_calibrate_sets_the_neutral_from_the_held_seconds(live):
    tab, receiver, take_frames, folder, _ = live
    tab.page.fill("#fc-hold", "1")
    tab.page.click("#fc-calibrate")
    tab.until("window.faceclean.state.calibration || window.faceclean.errors.length")
    assert tab.js("window.faceclean.errors") == []
    facts = tab.js("window.faceclean.state.calibration")
    assert "calibrated" in tab.page.inner_text("#fc-calibration")
    assert tab.js("window.faceclean.countdown")[0].startswith("hold a neutral face… 1.0 s")
    t0, t1 = facts["hold"]  # sender times s of the first and last frame held
    assert t1 - t0 >= 1.0 and facts["frames"] >= 5  # a second held, 5 frames at least
    # the neutral is the median of the input over the held second: the frames the relay
    # cleaned then (those the receiver got; a relay that lags skips stale ones)
    got = [t for t, _ in receiver.frames if t0 - 1e-4 <= t <= t1 + 1e-4]
    held = [_sent(take_frames, t) for t in got]
    assert len(held) == facts["frames"]
    for name in ("jawOpen", "eyeBlinkLeft", "mouthSmileLeft", "browInnerUp"):
        column = [f.values[f.names.index(name)] for f in held]
        assert facts["channels"][name]["neutral"] == pytest.approx(np.median(column), abs=1e-6)
    # ... and the levels file saved from the page maps it to 0 (--calibration reads it)
    tab.page.fill("#fc-path", str(folder / "neutral.json"))
    tab.note_after("#fc-save-levels", "saved levels")
    from faceclean.adjust import Adjust

    rules = Adjust.load(folder / "neutral.json").rules
    offsets = {p: v for p, k, v in rules if k == "offset"}
    neutral = facts["channels"]["jawOpen"]["neutral"]  # (facts: 6 decimals)
    assert offsets["jawOpen"] == pytest.approx(neutral, abs=1e-6)


def test_the_page_records_the_session(live):
    tab, _, _, folder, _ = live
    tab.page.fill("#fc-path", str(folder / "page.csv"))
    (folder / "page.clean.csv").write_text("an older session's")  # replaced, and said
    tab.note_after("#fc-record", "recording to")
    assert tab.js("window.faceclean.notes.at(-1)").endswith(
        f"(replacing {folder / 'page.clean.csv'} when it stops)")  # fmt: skip
    tab.until(f"window.faceclean.frames > {tab.js('window.faceclean.frames') + 30}")
    tab.note_after("#fc-record", "recorded")
    assert tab.js("window.faceclean.notes.at(-1)").endswith(
        f"(replacing {folder / 'page.clean.csv'})"
    )
    anim = io.load(folder / "page.csv")
    assert anim.n_frames >= 30 and io.load(folder / "page.clean.csv").n_frames == anim.n_frames


def test_a_request_without_the_token_is_refused(live, browser):
    tab, *_, url = live
    bare = url.split("?")[0]
    page = browser.new_page()
    assert page.goto(bare).status == 403
    assert "no valid token" in page.inner_text("body")
    assert page.goto(bare + "ui.js").status == 403
    page.close()


def test_a_page_drawn_on_the_cpu_lets_its_browser_yield_to_the_relay(browser):
    """relay --ui: the page (SwiftShader here) says it draws on the CPU, and the relay lowers
    its browser to the nice --ui-nice asks (ui/priority.py): every thread, and its sessions
    where it has them; never the relay's own. A browser of its own: the module's one keeps
    its weight."""
    from helpers import free_port

    from faceclean.ui import priority

    ports = free_port(), free_port()
    relay, url = start(["relay", "--listen", f"vmc://127.0.0.1:{ports[0]}", "--send",
                        f"livelink://127.0.0.1:{ports[1]}", "--ui", "--ui-nice", "7"])  # fmt: skip
    nice = os.getpriority(os.PRIO_PROCESS, relay.pid)
    group = (priority.PROC / str(relay.pid) / "autogroup").read_text()

    def ours(pid: int) -> bool:  # under this test's process: another worker's browser is not
        seen = set()
        while pid > 1 and pid not in seen:
            seen.add(pid)
            if pid == os.getpid():
                return True
            pid = priority._parent(pid) or 0
        return False

    def chromium() -> set[int]:
        return {p for p in priority._pids()
                if "chrom" in os.path.basename(priority._exe(p) or "") and ours(p)}  # fmt: skip

    before = chromium()  # the module's browser: not the page's, so it keeps its weight
    with reaped(relay):
        b = browser.browser_type.launch(executable_path=str(CHROMIUM), args=BROWSER_ARGS)
        try:
            tab = Tab(b, url)
            tab.until("window.faceclean.softwareGL === true")

            def lowered() -> tuple[int, int]:
                """(the page's browser's threads, those at nice 7 or more)."""
                threads = at = 0
                for pid in chromium() - before:
                    with contextlib.suppress(OSError):
                        for task in (priority.PROC / str(pid) / "task").iterdir():
                            threads += 1
                            at += os.getpriority(os.PRIO_PROCESS, int(task.name)) >= 7
                return threads, at

            def done() -> bool:  # all but any started since (the relay sets one by one)
                threads, at = lowered()
                return at > 0.9 * threads

            deadline = time.monotonic() + 20
            while not done() and time.monotonic() < deadline:
                tab.page.wait_for_timeout(50)  # the relay reads /proc in a thread of its own
            threads, at = lowered()
            assert at > 0.9 * threads, (threads, at)  # all but any started since
            assert os.getpriority(os.PRIO_PROCESS, relay.pid) == nice
            assert (priority.PROC / str(relay.pid) / "autogroup").read_text() == group
        finally:
            b.close()
        out, err = interrupt(relay)
    assert "the page draws on the CPU: its browser's " in out, err
    assert "yield to the relay (nice 7)" in out, err
    r = main(["relay", "--listen", "vmc://127.0.0.1:9", "--send", "livelink://127.0.0.1:9",
              "--ui", "--ui-nice", "20"])  # fmt: skip
    assert r == 2


def test_a_recording_the_page_started_is_saved_and_said_when_the_relay_is_stopped(tmp_path):
    # Ctrl-C while the page recorded: the relay stopped, and the recording was lost unsaid
    import json

    from helpers import free_port
    from websockets.sync.client import connect

    port = free_port()
    relay, url = start(["relay", "--listen", f"vmc://127.0.0.1:{port}", "--send",
                        f"livelink://127.0.0.1:{free_port()}", "--method", "one-euro", "--ui",
                        "--ui-nice", "0"], stderr=subprocess.DEVNULL)  # fmt: skip
    replay = subprocess.Popen([sys.executable, "-m", "faceclean", "replay",
                               str(first_take("neurosync")), "--loop", "--send",
                               f"vmc://127.0.0.1:{port}"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, env=ENV)  # fmt: skip
    out = tmp_path / "page.csv"
    ws_url = url.replace("http://", "ws://").replace("/?token=", "/live?token=")
    with reaped(relay), reaped(replay):
        with connect(ws_url, max_size=None) as ws:
            ws.send(json.dumps({"type": "record", "action": "start", "path": str(out)}))
            frames = 0
            while frames < 20:  # pushed frames: the stream runs through the recorder
                m = ws.recv(timeout=30)
                frames += isinstance(m, str) and m.startswith('{"type":"frames"')
        replay.kill()
        said, _ = interrupt(relay)
    assert "the page's recording:" in said and str(out) in said, said
    take, cleaned = io.load(out), io.load(tmp_path / "page.clean.csv")
    assert take.n_frames >= 5 and cleaned.n_frames == take.n_frames
