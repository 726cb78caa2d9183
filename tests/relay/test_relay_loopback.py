"""The relay end to end over loopback, python-osc as the peer on both sides: delivery,
cleaning, garbage, ordering, silences, NaN, passthrough, signals, replay."""

from __future__ import annotations

import contextlib
import select
import signal
import socket
import subprocess
import sys
import threading

import numpy as np
import pytest
from helpers import REPO, first_take, interrupt, reaped, shared
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.osc_packet import OscPacket
from pythonosc.osc_server import BlockingOSCUDPServer
from pythonosc.udp_client import UDPClient

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.relay import Relay, livelink, parse
from faceclean.relay.frame import Frame
from faceclean.relay.replay import frames_from_animation, replay
from faceclean.resolve import resolve

WAIT = 5.0  # s; the most any single event may take before the test gives up


class VmcPeer:
    """A python-osc server collecting VMC frames (dict name -> value) and other messages."""

    def __init__(self) -> None:
        self.frames: list[dict[str, float]] = []
        self.other: list[tuple[str, list]] = []
        self._current: dict[str, float] = {}
        self._cond = threading.Condition()
        d = Dispatcher()
        d.map("/VMC/Ext/Blend/Val", self._val)
        d.map("/VMC/Ext/Blend/Apply", self._apply)
        d.set_default_handler(lambda address, *args: self.other.append((address, list(args))))
        self.server = BlockingOSCUDPServer(("127.0.0.1", 0), d)
        self.port = self.server.server_address[1]
        self._thread = threading.Thread(
            target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True
        )
        self._thread.start()

    def _val(self, address: str, name: str, value: float) -> None:
        self._current[name] = value

    def _apply(self, address: str, *args: object) -> None:
        with self._cond:
            self.frames.append(self._current)
            self._current = {}
            self._cond.notify_all()

    def wait_for(self, n: int, timeout: float = WAIT) -> bool:
        with self._cond:
            return self._cond.wait_for(lambda: len(self.frames) >= n, timeout)

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        self._thread.join(WAIT)


@contextlib.contextmanager
def vmc_peer():
    peer = VmcPeer()
    try:
        yield peer
    finally:
        peer.close()


@contextlib.contextmanager
def running(listen: str, send: str, method: str = "ema"):
    """A relay serving in a thread; stopped and closed on exit."""
    relay = Relay(parse(listen), parse(send, "send"), resolve(method).build())
    thread = threading.Thread(target=relay.run, daemon=True)
    thread.start()
    try:
        yield relay
    finally:
        relay.stop()
        thread.join(WAIT)
        relay.close()
    assert not thread.is_alive()


@contextlib.contextmanager
def raw_receiver():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(WAIT)
    try:
        yield sock
    finally:
        sock.close()


def vmc_bundle(names, values, t=None, extra=()):
    """A VMC frame built with python-osc: [/VMC/Ext/T], extra messages, Vals, Apply."""
    b = OscBundleBuilder(IMMEDIATELY)
    msgs = ([("/VMC/Ext/T", [float(t)])] if t is not None else []) + list(extra)
    msgs += [("/VMC/Ext/Blend/Val", [n, float(v)]) for n, v in zip(names, values, strict=True)]
    for address, args in msgs + [("/VMC/Ext/Blend/Apply", [])]:
        m = OscMessageBuilder(address)
        for a in args:
            m.add_arg(a)
        b.add_content(m.build())
    return b.build()


def jitter(x: np.ndarray) -> float:
    """Mean squared second difference over frames and channels."""
    return float(np.mean(np.diff(x, 2, axis=0) ** 2))


def real_take(n: int = 600) -> np.ndarray:
    """(n, 52) values of a real 60 fps ARKit take."""
    from faceclean import load

    values, _ = load(first_take("neurosync")).arkit()
    values = values[~np.isnan(values).all(axis=1)]
    return values[:n]


GARBAGE = [b"", b"garbage", b"\x00\x01\x02\x03", b"#bundle\x00", b"{json: 1}", b"\xff" * 300]


def test_vmc_stream_comes_out_cleaned_through_garbage():
    truth = real_take()
    rng = np.random.default_rng(1)
    noisy = np.clip(truth + rng.normal(0.0, 0.02, truth.shape), 0.0, 1.0)
    with vmc_peer() as peer, running("vmc://127.0.0.1:0", f"vmc://127.0.0.1:{peer.port}") as r:
        client = UDPClient("127.0.0.1", r.address.port)
        junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        n_garbage = 0
        for i, row in enumerate(noisy):
            before = len(peer.frames)
            client.send(vmc_bundle(ARKIT52, row, t=i / 60.0))  # 60 fps by its timestamps
            if i % 7 == 3:
                junk.sendto(GARBAGE[n_garbage % len(GARBAGE)], ("127.0.0.1", r.address.port))
                n_garbage += 1
            peer.wait_for(before + 1, 1.0)
        junk.close()
        assert peer.wait_for(int(0.95 * len(noisy)))
        stats = r.stats
        client._sock.setblocking(False)
        with pytest.raises(BlockingIOError):  # nothing ever goes back to the sender
            client._sock.recv(65536)
    assert len(peer.frames) >= 0.95 * len(noisy)
    assert stats.malformed == n_garbage
    assert stats.frames_in == len(noisy) and stats.frames_out == len(peer.frames)
    out = np.array([[f[n] for n in ARKIT52] for f in peer.frames])
    assert out.shape[1] == 52 and np.isfinite(out).all()
    assert jitter(out) < 0.5 * jitter(noisy)  # smoother than what went in
    assert np.abs(out - noisy[: len(out)]).max() > 0.01  # actually changed


def test_recorded_livelink_packets_come_out_as_vmc_frames():
    packets = livelink.read_recording(shared("raw_streams", "llv_dao.gesichter"))
    ref = np.load(shared("raw_streams", "llv_dao.npz"))
    with (
        vmc_peer() as peer,
        running("livelink://127.0.0.1:0", f"vmc://127.0.0.1:{peer.port}") as r,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx,
    ):
        for i, p in enumerate(packets):
            tx.sendto(p, ("127.0.0.1", r.address.port))
            peer.wait_for(i + 1, 1.0)
        stats = r.stats
    assert len(peer.frames) == len(packets) == 180
    assert stats.dropped == 0 and stats.malformed == 0
    assert list(peer.frames[0]) == list(ARKIT52)  # ARKit "perfect sync" names
    out = np.array([[f[n] for n in ARKIT52] for f in peer.frames])
    np.testing.assert_array_equal(out[0], ref["weights"][0])  # the first frame starts the state
    assert jitter(out) < jitter(ref["weights"].astype(np.float64))


def ll(t: float, values: np.ndarray) -> bytes:
    """A Live Link sender's packet with ``values`` as given (a sender may send NaN; our
    Encoder never does): the encoder's header and timing, then the 61 floats."""
    packet = livelink.Encoder().encode(Frame(ARKIT52, np.zeros(52), t))
    floats = np.zeros(livelink.N_SHAPES + livelink.N_POSE)
    floats[:52] = values
    return packet[: -4 * len(floats)] + floats.astype(">f4").tobytes()


def test_order_duplicates_silence_nan_and_restart():
    rng = np.random.default_rng(2)
    v = rng.uniform(0.2, 0.8, (10, 52)).astype(np.float32).astype(np.float64)
    with (
        vmc_peer() as peer,
        running("livelink://127.0.0.1:0", f"vmc://127.0.0.1:{peer.port}") as r,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx,
    ):
        to = ("127.0.0.1", r.address.port)

        def deliver(packet: bytes, n: int) -> np.ndarray:
            tx.sendto(packet, to)
            assert peer.wait_for(n)
            return np.array([peer.frames[-1][k] for k in ARKIT52])

        t0 = 1000.0
        for i in range(3):
            deliver(ll(t0 + i / 60, v[i]), i + 1)
        tx.sendto(ll(t0 + 2 / 60, v[3]), to)  # duplicate
        tx.sendto(ll(t0 + 1 / 60, v[4]), to)  # late
        last = deliver(ll(t0 + 3 / 60, v[5]), 4)
        assert r.stats.out_of_order == 2 and r.stats.frames_out == 4

        back = deliver(ll(t0 + 3600.0, v[6]), 5)  # an hour of silence: restart, no jump
        np.testing.assert_array_equal(back, v[6])

        x = v[7].copy()
        x[5] = np.nan
        y = deliver(ll(t0 + 3600.0 + 1 / 60, x), 6)  # NaN channel: held, others advance
        assert np.isfinite(y).all() and y[5] == np.float32(back[5])
        assert not np.array_equal(y, back)

        held = deliver(ll(t0 + 3600.0 + 2 / 60, np.full(52, np.nan)), 7)  # all NaN
        np.testing.assert_array_equal(held, y)
        assert r.stats.missing == 1

        fresh = deliver(ll(t0 + 3000.0, v[8]), 8)  # the sender restarted its clock
        np.testing.assert_array_equal(fresh, v[8])
        assert r.stats.restarts == 1
    assert not np.array_equal(last, v[5])  # frames in between were cleaned


def test_only_the_newest_waiting_frame_is_sent():
    v = np.linspace(0.25, 0.75, 3 * 52).reshape(3, 52).astype(np.float32).astype(np.float64)
    with raw_receiver() as rx:
        relay = Relay(parse("livelink://:0"), parse(f"vmc://:{rx.getsockname()[1]}", "send"),
                      resolve("ema").build())  # fmt: skip
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for i in range(3):  # all three wait in the socket before the relay runs
                tx.sendto(ll(10.0 + i / 60, v[i]), ("127.0.0.1", relay.address.port))
        thread = threading.Thread(target=relay.run, daemon=True)
        thread.start()
        msgs = OscPacket(rx.recv(65536)).messages
        relay.stop()
        thread.join(WAIT)
        relay.close()
        rx.settimeout(0.0)
        with pytest.raises(BlockingIOError):  # one frame out, not three
            rx.recv(65536)
    vals = [m.message for m in msgs if m.message.address == "/VMC/Ext/Blend/Val"]
    got = np.array([m.params[1] for m in vals])
    np.testing.assert_array_equal(got, v[2])  # the newest, which starts the cleaner
    assert relay.stats.stale == 2 and relay.stats.frames_out == 1


def test_vmc_to_livelink_and_passthrough():
    names = ("EyeBlink_L", "jawOpen", "Joy")  # ARKit in two spellings + a VRM clip
    with (
        raw_receiver() as rx,
        running("vmc://127.0.0.1:0", f"livelink://127.0.0.1:{rx.getsockname()[1]}") as r,
    ):
        UDPClient("127.0.0.1", r.address.port).send(vmc_bundle(names, [1.0, 0.5, 0.25], t=4.0))
        f = livelink.decode(rx.recv(65536))
    assert f.values[ARKIT52.index("eyeBlinkLeft")] == 1.0 and f.values[17] == 0.5
    assert np.count_nonzero(f.values) == 2 and np.isnan(f.pose).all()  # zeros: not tracked
    assert f.t == pytest.approx(4.0)

    root = ("/VMC/Ext/Root/Pos", ["root", 1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0])
    bones = OscBundleBuilder(IMMEDIATELY)
    m = OscMessageBuilder("/VMC/Ext/Bone/Pos")
    for a in ["Spine", 0.0, 1.5, 0.0, 0.0, 0.0, 0.0, 1.0]:  # Head/eyes: the pose (vmc.py)
        m.add_arg(a)
    bones.add_content(m.build())
    bones = bones.build().dgram
    with (
        raw_receiver() as rx,
        running("vmc://127.0.0.1:0", f"vmc://127.0.0.1:{rx.getsockname()[1]}") as r,
    ):
        client = UDPClient("127.0.0.1", r.address.port)
        client.send(vmc_bundle(names, [1.0, 0.5, 0.25], extra=[root]))
        got = [(m.message.address, m.message.params) for m in OscPacket(rx.recv(65536)).messages]
        client._sock.sendto(bones, ("127.0.0.1", r.address.port))
        assert rx.recv(65536) == bones  # a datagram without blendshapes: unchanged
        assert r.stats.passthrough == 1
    assert got[0] == root  # other addresses pass through untouched
    vals = [("/VMC/Ext/Blend/Val", [n, v]) for n, v in zip(names, [1.0, 0.5, 0.25], strict=True)]
    assert got[1:4] == vals
    assert got[4] == ("/VMC/Ext/Blend/Apply", [])


def test_ifacialmocap_input_uses_arrival_time():
    with (
        vmc_peer() as peer,
        running("ifacialmocap://127.0.0.1:0", f"vmc://127.0.0.1:{peer.port}") as r,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx,
    ):
        to = ("127.0.0.1", r.address.port)
        tx.sendto(b"eyeBlink_L-100|jawOpen-50|=head#1,2,3,0,0,0|", to)
        assert peer.wait_for(1)
        tx.sendto(b"eyeBlink_L-0|jawOpen-50|", to)
        assert peer.wait_for(2)
    assert peer.frames[0] == {"eyeBlink_L": 1.0, "jawOpen": 0.5}
    assert 0.0 < peer.frames[1]["eyeBlink_L"] < 1.0  # smoothed on arrival times


@pytest.mark.parametrize("scheme", ["vmc", "livelink"])
def test_relay_survives_a_flood_of_random_and_truncated_datagrams(scheme):
    rng = np.random.default_rng(3)
    good = vmc_bundle(ARKIT52, np.full(52, 0.5)).dgram if scheme == "vmc" else None
    with (
        vmc_peer() as peer,
        running(f"{scheme}://127.0.0.1:0", f"vmc://127.0.0.1:{peer.port}") as r,
    ):
        to = ("127.0.0.1", r.address.port)
        sent = 0
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for burst in range(12):
                frame = vmc_bundle(ARKIT52, np.full(52, 0.5), t=burst) if good else None
                packet = frame.dgram if frame else ll(burst, np.full(52, 0.5))
                for _ in range(100):
                    if rng.random() < 0.5:
                        junk = rng.bytes(int(rng.integers(0, 1200)))
                        junk = b"\x00" + junk if junk[:1] in (b"/", b"#", b"\x06") else junk
                    else:
                        junk = packet[: int(rng.integers(0, len(packet) - 4))]
                    tx.sendto(junk, to)
                    sent += 1
                tx.sendto(packet, to)
                assert peer.wait_for(burst + 1)
        stats = r.stats
    assert len(peer.frames) == 12
    if scheme == "livelink":
        assert stats.malformed == sent  # every one of them, and nothing else
    else:  # a cut at a bundle element boundary is a valid (partial) bundle
        assert stats.malformed >= 0.8 * sent


def _listening(proc: subprocess.Popen, timeout: float = 30.0) -> int:
    """The port a relay started by ``_start`` listens on, once its banner is out."""
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    assert ready, "relay did not start"
    return int(proc.stdout.readline().split()[1].rsplit(":", 1)[1])


def _start(sig_args: list[str]) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "faceclean", "relay", *sig_args]
    return subprocess.Popen(
        cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_relay_process_stops_cleanly_on_signals(sig):
    with raw_receiver() as rx:
        proc = _start(
            ["--listen", "vmc://127.0.0.1:0", "--send", f"vmc://127.0.0.1:{rx.getsockname()[1]}"]
            + ["--method", "ema", "--stats", "60"]
        )
        try:
            port = _listening(proc)
            UDPClient("127.0.0.1", port).send(vmc_bundle(["jawOpen"], [0.25]))
            frame = OscPacket(rx.recv(65536)).messages
            proc.send_signal(sig)
            out, err = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert frame[0].message.params == ["jawOpen", 0.25]
    assert proc.returncode == 0, err
    assert "stopped: in 1 out 1 dropped 0" in out and "Traceback" not in err


def _idle(host: str, *more: str) -> tuple[str, str]:
    """(stdout, stderr) of a relay listening on ``host`` that hears nothing, stopped by
    Ctrl-C once it listens; its exit status checked (0)."""
    with raw_receiver() as rx:
        proc = _start(
            ["--listen", f"vmc://{host}:0", "--send", f"vmc://127.0.0.1:{rx.getsockname()[1]}"]
            + ["--method", "ema", *more]
        )
        with reaped(proc):
            _listening(proc)  # the banner: it listens
            out, err = interrupt(proc)
    assert proc.returncode == 0, err
    return out, err


def test_an_idle_relay_says_it_has_no_latency_yet_not_nan():
    # issue 19: a relay stopped before any frame printed "latency p50 nan ms"
    out, _ = _idle("127.0.0.1")
    stopped = next(ln for ln in out.splitlines() if ln.startswith("stopped:"))
    assert "nan" not in stopped and "latency - (no frames sent yet)" in stopped


def test_an_idle_recording_relay_says_it_wrote_nothing_and_a_wide_listen_is_warned(tmp_path):
    # issue 19 review: --record with no frame wrote no file and said nothing; a listen on
    # every interface warned only in the README
    record = tmp_path / "rec.csv"
    out, err = _idle("0.0.0.0", "--record", str(record))
    assert "recorded nothing: no frame was sent, so no file was written" in out
    assert not record.exists() and list(tmp_path.iterdir()) == []
    [warning] = [ln for ln in err.splitlines() if ln.strip()]
    assert warning.startswith("faceclean: warning: listening on 0.0.0.0: anyone who can reach")


@pytest.mark.parametrize("record", ["", "  "])
def test_an_empty_record_name_is_refused(capsys, record):
    # third red team: --record '' ran without recording, unsaid
    args = ["relay", "--listen", "vmc://127.0.0.1:0", "--send", "vmc://127.0.0.1:9"]
    assert main([*args, "--record", record]) == 2
    assert capsys.readouterr().err.strip() == "faceclean: --record: give a file name (.csv or .npz)"


@pytest.mark.parametrize("ui", [False, True])
def test_a_record_over_a_file_the_relay_reads_is_refused_before_it_starts(tmp_path, ui):
    # --record naming the relay's own --model: warned at the start, refused at the end,
    # the whole session lost
    import shutil

    from faceclean.resolve import model_file

    model = tmp_path / "mine.npz"
    shutil.copy(model_file("default"), model)
    args = ["relay", "--listen", "vmc://127.0.0.1:0", "--send", "vmc://127.0.0.1:9",
            "--model", str(model), "--record", str(model)]  # fmt: skip
    args += ["--ui", "--no-browser"] if ui else []
    # (a subprocess: the old relay ran on, and a timeout fails where main() would hang)
    done = subprocess.run([sys.executable, "-m", "faceclean", *args], capture_output=True,
                          text=True, timeout=60)  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "is a file this command reads" in done.stderr and "will replace" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


@pytest.mark.parametrize("extra, said", [
    (["--calibrate-seconds", "1e400"], "--calibrate-seconds must be over 0 and at most 3600"),
    (["--calibrate-seconds", "100", "--ui", "--no-browser"], "at most 60 (got 100)"),
    (["--ui", "--no-browser", "--ui-port", "70000"], "--ui-port must be in 0..65535"),
])  # fmt: skip
def test_a_hold_that_never_ends_and_a_page_port_out_of_range_are_one_line(extra, said):
    # --calibrate-seconds 1e400 (inf) calibrated forever; --ui-port's message said --port
    args = ["relay", "--listen", "vmc://127.0.0.1:0", "--send", "vmc://127.0.0.1:9", *extra]
    done = subprocess.run([sys.executable, "-m", "faceclean", *args], capture_output=True,
                          text=True, timeout=60)  # fmt: skip
    assert done.returncode == 2 and said in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


@pytest.mark.parametrize("host,loopback", [("127.0.0.1", True), ("127.0.0.2", True),
                                           ("localhost", True), ("::1", True), ("0.0.0.0", False),
                                           ("::", False), ("192.168.1.20", False),
                                           ("myhost.local", False)])  # fmt: skip
def test_which_listen_hosts_are_loopback(host, loopback):
    from faceclean.cli.relay import _loopback

    assert _loopback(host) is loopback


def test_relay_command_errors_are_one_line(capsys):
    assert main(["relay", "--listen", "vmc://:0", "--send", "ifacialmocap://:4"]) == 2
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        assert main(["relay", "--listen", f"vmc://:{port}", "--send", "vmc://:9"]) == 2
    assert (
        main(["relay", "--listen", "vmc://:0", "--send", "vmc://:9", "--method", "gaussian"]) == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(e.startswith("faceclean: ") for e in err)
    assert "cannot relay" in err[1] and "offline" in err[2]


def test_relay_listens_on_localhost_by_default():
    with raw_receiver() as rx, running("vmc://:0", f"vmc://:{rx.getsockname()[1]}") as r:
        assert r.address.host == "127.0.0.1"


def test_replay_paces_by_timestamps_with_an_injected_clock():
    times = np.array([0.0, 0.02, 0.05, 0.07])
    values = np.linspace(0.0, 1.0, 4)[:, None] * np.ones((4, 52))
    values[2] = np.nan  # tracking loss: nothing sent
    frames = frames_from_animation(Animation.from_arkit(times + 10.0, values))
    now = [100.0]
    deadlines: list[float] = []
    stop = threading.Event()

    def wait(deadline: float) -> None:
        deadlines.append(deadline)
        now[0] = max(now[0], deadline)
        if len(deadlines) == 6:
            stop.set()

    with raw_receiver() as rx:
        port = rx.getsockname()[1]
        n = replay(frames, parse(f"vmc://:{port}", "send"), speed=2.0, loop=True, stop=stop,
                   clock=lambda: now[0], wait=wait)  # fmt: skip
        got = [OscPacket(rx.recv(65536)).messages for _ in range(n)]
    assert n == 5
    sent_t = [m[0].message.params[0] for m in got]  # /VMC/Ext/T
    cycle = 0.07 + 0.035  # one pass + the median period (of 0.02 and 0.05)
    np.testing.assert_allclose(sent_t, [0.0, 0.02, 0.07, cycle, cycle + 0.02], atol=1e-6)
    np.testing.assert_allclose(deadlines[:5], 100.0 + np.array(sent_t) / 2.0, atol=1e-6)
    assert got[1][1].message.params == ["eyeBlinkLeft", pytest.approx(1 / 3)]


def test_replay_command_streams_a_recording_as_livelink(capsys):
    ref = np.load(shared("raw_streams", "llv_dao.npz"))
    with raw_receiver() as rx:
        rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        url = f"livelink://127.0.0.1:{rx.getsockname()[1]}"
        path = str(shared("raw_streams", "llv_dao.gesichter"))
        assert main(["replay", path, "--send", url, "--speed", "200"]) == 0
        frames = [livelink.decode(rx.recv(65536)) for _ in range(180)]
    assert "sent 180 packets" in capsys.readouterr().out
    np.testing.assert_array_equal([f.values for f in frames], ref["weights"])
    # the packets' own timecode, not one restarted at frame 0
    np.testing.assert_array_equal([f.timecode[0] for f in frames], ref["frame_number"])
    np.testing.assert_array_equal([f.timecode[1] for f in frames], ref["sub_frame"])


def test_replay_to_an_address_it_cannot_send_to_is_one_line(capsys):
    # a broadcast address: "[Errno 13] Permission denied", exit 1
    path = str(shared("raw_streams", "llv_dao.gesichter"))
    assert main(["replay", path, "--send", "livelink://255.255.255.255:5"]) == 2
    err = capsys.readouterr().err
    assert "cannot send to 255.255.255.255 port 5" in err and "Errno" not in err, err


def test_relay_passes_every_frame_from_its_first_packet_on():
    """The shipped LSTM (numba kernel), as a user starts it: a stream's first 61 frames, paced as a
    tracker sends them, come out whole; before the warm-up, the LSTM's first advancing
    step compiled for 0.4-1.8 s and 24-27 frames were stale. (A 33 ms gap between packets
    leaves room for a loaded machine; a compile at the start is ten times longer.)"""
    import time

    from faceclean.datasets.performer import perform

    take = perform(1.0, 11, fps=60.0).values.astype(np.float32).astype(np.float64)
    with vmc_peer() as peer:
        send = f"vmc://127.0.0.1:{peer.port}"
        proc = _start(["--listen", "vmc://127.0.0.1:0", "--send", send, "--method", "lstm"])
        with reaped(proc):
            port = _listening(proc, 120.0)  # the LSTM loads first
            client = UDPClient("127.0.0.1", port)
            for i, row in enumerate(take):  # the pace of a stream, not a wait for the relay:
                client.send(vmc_bundle(ARKIT52, row, t=i / 60.0))
                time.sleep(1 / 30)  # 30 packets/s, never a catch-up burst from a slow sender
            assert peer.wait_for(len(take), 30.0)
            out, err = interrupt(proc, timeout=60)
    n = len(take)
    assert f"stopped: in {n} out {n} dropped 0 (order 0, stale 0)" in out, out + err
    first = np.array([peer.frames[0][k] for k in ARKIT52])
    np.testing.assert_array_equal(first, take[0])  # the first packet itself starts the state


def test_a_recorded_session_replays_and_recleans_to_what_was_sent(tmp_path):
    from faceclean import io
    from faceclean.relay.recorder import Recorder

    rng = np.random.default_rng(4)
    v = rng.uniform(0.0, 1.0, (40, 52)).astype(np.float32).astype(np.float64)
    v[20] = np.nan  # tracking loss
    rec = Recorder(tmp_path / "session.npz")
    with vmc_peer() as peer:
        relay = Relay(parse("vmc://127.0.0.1:0"), parse(f"vmc://127.0.0.1:{peer.port}", "send"),
                      resolve("ema").build(), recorder=rec)  # fmt: skip
        thread = threading.Thread(target=relay.run, daemon=True)
        thread.start()
        client = UDPClient("127.0.0.1", relay.address.port)
        for i, row in enumerate(v):
            before = len(peer.frames)
            client.send(vmc_bundle(ARKIT52, row, t=5.0 + i / 60.0))
            assert peer.wait_for(before + 1)
        relay.stop()
        thread.join(WAIT)
        relay.close()
    take_path, clean_path = rec.save()
    assert clean_path.name == "session.clean.npz"
    take, cleaned = io.load(take_path), io.load(clean_path)
    np.testing.assert_allclose(take.times, np.arange(40) / 60.0, atol=1e-6)  # from 0 (float32)
    np.testing.assert_array_equal(take.values, v)  # the input, exactly, NaN row included
    sent = np.array([[f[k] for k in ARKIT52] for f in peer.frames])
    np.testing.assert_allclose(cleaned.values, sent, atol=1e-6)  # the output, as it went out
    again = resolve("ema").build().clean(take)  # the recording re-cleans to the same output
    np.testing.assert_allclose(np.delete(again.values, 20, 0), np.delete(sent, 20, 0), atol=1e-6)
    np.testing.assert_array_equal(cleaned.values[20], cleaned.values[19])  # held, as sent

    with vmc_peer() as peer:  # and replays as a live stream
        assert main(["replay", str(take_path), "--send", f"vmc://127.0.0.1:{peer.port}",
                     "--speed", "20"]) == 0  # fmt: skip
        assert peer.wait_for(39)
    replayed = np.array([[f[k] for k in ARKIT52] for f in peer.frames])
    np.testing.assert_array_equal(replayed, np.delete(v, 20, axis=0))


def test_a_sender_restart_goes_on_after_a_gap_in_the_recording(tmp_path):
    from faceclean.relay.recorder import GAP, Recorder

    rec = Recorder(tmp_path / "s.csv")
    x = np.full(52, 0.5)
    for t in (100.0, 100.5, 101.0):
        rec.add(t, x, x, None)
    rec.restart()
    rec.add(3.0, x, x, None)
    take, _ = rec.animations()
    np.testing.assert_allclose(take.times, [0.0, 0.5, 1.0, 1.0 + GAP])
    with pytest.raises(FacecleanError, match=r"\.csv \(Live Link\) or \.npz"):
        Recorder(tmp_path / "s.json")
    with pytest.raises(FacecleanError, match="does not exist"):
        Recorder(tmp_path / "absent" / "s.csv")


def test_relay_calibrates_the_neutral_from_its_first_seconds(capsys):
    from faceclean.calibration import LiveCalibration

    n = 120  # 2 s at 60 fps: 1 s neutral (jawOpen rests at 0.2), then the jaw opens
    v = np.full((n, 52), 0.05)
    v[:, 17] = 0.2
    v[90:, 17] = 0.9
    v[100:104, 0] = 0.95  # a blink after the calibration
    v = v.astype(np.float32).astype(np.float64)
    done = []
    cleaner = LiveCalibration(resolve("ema").build(), 1.0, on_done=done.append)
    with vmc_peer() as peer:
        relay = Relay(parse("vmc://127.0.0.1:0"), parse(f"vmc://127.0.0.1:{peer.port}", "send"),
                      cleaner)  # fmt: skip
        thread = threading.Thread(target=relay.run, daemon=True)
        thread.start()
        client = UDPClient("127.0.0.1", relay.address.port)
        for i, row in enumerate(v):
            before = len(peer.frames)
            client.send(vmc_bundle(ARKIT52, row, t=i / 60.0))
            assert peer.wait_for(before + 1)
        relay.stop()
        thread.join(WAIT)
        relay.close()
    out = np.array([[f[k] for k in ARKIT52] for f in peer.frames])
    assert len(out) == n and len(done) == 1  # every frame relayed, calibrated once
    np.testing.assert_allclose(out[:60, 17], 0.2, atol=1e-6)  # passed through meanwhile
    assert abs(out[85, 17]) < 1e-3  # then the neutral reads 0
    assert out[-1, 17] == pytest.approx((0.9 - 0.2) / 0.8, abs=0.02)  # and 1 still maps to 1
    assert out[100:110, 0].max() > 0.7  # a blink still closes


def test_relay_command_records_a_session_with_levels(tmp_path, capsys):
    session = tmp_path / "session.csv"
    (tmp_path / "session.clean.csv").write_text("an older session's")  # replaced, and said
    with raw_receiver() as rx:
        proc = _start(
            ["--listen", "vmc://127.0.0.1:0", "--send", f"vmc://127.0.0.1:{rx.getsockname()[1]}"]
            + ["--method", "ema", "--set", "jawOpen.gain=2", "--calibrate-seconds", "0.05"]
            + ["--record", str(session)]
        )
        with reaped(proc):
            port = _listening(proc)
            client = UDPClient("127.0.0.1", port)
            for i in range(30):
                client.send(vmc_bundle(["jawOpen", "eyeBlinkLeft"], [0.25, 0.1], t=i / 60.0))
                OscPacket(rx.recv(65536))
            out, err = interrupt(proc, timeout=30)
    assert proc.returncode == 0, err
    assert "calibrated the neutral of 2 channels" in out
    assert f"recorded 30 frames: {session} (input), {tmp_path / 'session.clean.csv'} (cleaned, " \
           "replaced)" in out  # fmt: skip
    assert f"--record will replace {tmp_path / 'session.clean.csv'} when" in err
    from faceclean import io

    take, cleaned = io.load(session), io.load(tmp_path / "session.clean.csv")
    assert take.meta["format"] == "livelink" and take.n_frames == 30
    np.testing.assert_allclose(take.channel("jawOpen"), 0.25, atol=1e-6)
    assert cleaned.channel("jawOpen")[0] == pytest.approx(0.5, abs=1e-6)  # gain 2 before
    assert abs(cleaned.channel("jawOpen")[-1]) < 0.01  # the neutral, once calibrated
    assert main(["relay", "--listen", "vmc://:0", "--send", "vmc://:9", "--record", "x.json"]) == 2
    assert "--record x.json" in capsys.readouterr().err


def test_replay_stopped_by_a_signal_says_so_not_refused(tmp_path):
    from faceclean import io

    take = tmp_path / "take.npz"
    io.save(Animation.from_arkit(np.arange(600) / 60.0, np.full((600, 52), 0.5)), take)
    with raw_receiver() as rx:
        cmd = [sys.executable, "-m", "faceclean", "replay", str(take), "--send"]
        proc = subprocess.Popen(
            [*cmd, f"vmc://127.0.0.1:{rx.getsockname()[1]}"],
            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        with reaped(proc):
            rx.recv(65536)  # the first packet is out: the replay is running
            out, err = interrupt(proc, timeout=30)
    assert proc.returncode == 0, err
    assert "not sent)" in out and "stopped;" in out and "refused" not in out


def test_a_second_signal_while_the_recording_is_saved_loses_nothing(tmp_path):
    # red team: under `timeout` (which signals the relay and its group: twice) or two
    # Ctrl-C, the second signal arrived while --record was being saved: "faceclean:
    # terminated", no file, the session lost unsaid. Now the first stops the relay and
    # every later one waits for the save.
    record = tmp_path / "rec.csv"
    with raw_receiver() as rx:
        proc = _start(["--listen", "vmc://127.0.0.1:0", "--send",
                       f"vmc://127.0.0.1:{rx.getsockname()[1]}", "--method", "ema",
                       "--record", str(record)])  # fmt: skip
        with reaped(proc):
            port = _listening(proc)
            sender = UDPClient("127.0.0.1", port)
            for k in range(300):
                sender.send(vmc_bundle(["jawOpen"], [k / 300]))
                rx.recv(65536)  # each frame through before the next
            proc.send_signal(signal.SIGTERM)
            while not (line := proc.stdout.readline()).startswith("stopped:"):
                assert line, "the relay ended before it said it stopped"
            proc.send_signal(signal.SIGTERM)  # as timeout's second, while it saves
            out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "recorded 300 frames" in out and "terminated" not in err
    from faceclean import io

    assert io.load(record).n_frames == 300
    assert io.load(tmp_path / "rec.clean.csv").n_frames == 300
