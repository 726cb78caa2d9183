"""Head pose and timecode through the relay: VMC Bone/Pos (python-osc as the peer), Live
Link angles and timecode (byte literals, then loopback), iFacialMocap's head, --record and
replay keeping the tracker's timecode, an arrival-time recording that says so."""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import pytest
from helpers import shared
from pythonosc.udp_client import UDPClient
from scipy.spatial.transform import Rotation
from test_relay_loopback import WAIT, raw_receiver, vmc_bundle, vmc_peer

from faceclean import io
from faceclean.channels import ARKIT52, POSE
from faceclean.cli import main
from faceclean.pose import gltf_quaternion, unity_angles, unity_angles_one, unity_quaternion
from faceclean.relay import Relay, livelink, parse, vmc
from faceclean.relay.frame import Frame
from faceclean.relay.recorder import ARRIVAL, Recorder
from faceclean.relay.replay import frames_from_recording, replay
from faceclean.resolve import resolve

DAY_FRAMES = 86400 * 60  # 60 fps frames in a day


def _relay(listen: str, send: str, recorder=None, method: str = "ema") -> Relay:
    choice = resolve(method)
    return Relay(
        parse(listen),
        parse(send, "send"),
        choice.build(),
        recorder=recorder,
        pose=choice.build_pose(),
    )


class _serving:
    def __init__(self, relay: Relay) -> None:
        self.relay = relay
        self.thread = threading.Thread(target=relay.run, daemon=True)

    def __enter__(self) -> Relay:
        self.thread.start()
        return self.relay

    def __exit__(self, *exc: object) -> None:
        self.relay.stop()
        self.thread.join(WAIT)
        self.relay.close()


def _jitter(x: np.ndarray) -> float:
    return float(np.mean(np.diff(x, 2, axis=0) ** 2))


# -- the convention ------------------------------------------------------------------------


def test_yaw_pitch_roll_and_quaternions_agree_with_scipy_and_unity_order():
    ypr = np.array([[0.4, -0.2, 0.1], [-1.0, 0.5, -0.3]])
    q = unity_quaternion(ypr)
    # Unity's Euler order: roll about Z first, then pitch about X, then yaw about Y
    for (yaw, pitch, roll), qi in zip(ypr, q, strict=True):
        want = (
            Rotation.from_euler("y", yaw) * Rotation.from_euler("x", pitch)
        ) * Rotation.from_euler("z", roll)
        assert Rotation.from_quat(qi).approx_equal(want, atol=1e-12)
    np.testing.assert_allclose(unity_angles(q), ypr, atol=1e-12)
    # a positive yaw turns the face (+Z) towards +X (the subject's right) in Unity
    forward = Rotation.from_quat(unity_quaternion(np.array([0.3, 0.0, 0.0]))).apply([0, 0, 1])
    assert forward[0] > 0
    # glTF: X mirrored (+X the face's left), so the same turn goes towards -X there
    g = Rotation.from_quat(gltf_quaternion(np.array([0.3, 0.0, 0.0]))).apply([0, 0, 1])
    assert g[0] < 0 and np.isclose(g[2], forward[2])
    assert np.isnan(unity_angles(np.zeros(4))).all()  # no rotation at all: no angles


def test_one_quaternions_angles_are_the_arrays():
    rng = np.random.default_rng(3)
    q = np.concatenate([rng.normal(size=(200, 4)), unity_quaternion(rng.uniform(-3, 3, (50, 3)))])
    odd = [[0, 0, 0, 0], [np.nan, 0, 0, 1], [np.inf, 0, 0, 1], [0, 0, 0, 1e-12], [0, 1, 0, 0]]
    q = np.concatenate([q, odd])
    one = np.array([unity_angles_one(tuple(v)) for v in q.tolist()])
    np.testing.assert_allclose(one, unity_angles(q), atol=1e-12)  # NaN where NaN


# -- VMC Bone/Pos --------------------------------------------------------------------------


def _bone(name: str, q, position=(0.0, 0.06, 0.01)):
    return ("/VMC/Ext/Bone/Pos", [name, *map(float, position), *map(float, q)])


def test_vmc_head_bone_becomes_the_pose_and_goes_back_out():
    ypr = np.array([0.25, -0.1, 0.05])
    hips = ("/VMC/Ext/Bone/Pos", ["Hips", 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    data = vmc_bundle(["jawOpen"], [0.5], extra=[_bone("Head", unity_quaternion(ypr)), hips]).dgram
    f = vmc.Decoder().feed(data)
    np.testing.assert_allclose(f.pose[:3], ypr, atol=1e-6)  # float32 on the wire
    assert np.isnan(f.pose[3:]).all()  # no eye bones: no eye angles
    assert f.positions == {"Head": pytest.approx((0.0, 0.06, 0.01))}
    assert len(f.passthrough) == 1  # Hips passes; Head is the pose now
    again = vmc.Decoder().feed(vmc.Encoder().encode(f))
    np.testing.assert_allclose(again.pose[:3], f.pose[:3], atol=1e-6)
    assert again.positions == f.positions and np.isnan(again.pose[3:]).all()


def test_vmc_bone_only_datagrams_pass_until_the_sender_sends_a_face():
    d = vmc.Decoder()
    from pythonosc.osc_message_builder import OscMessageBuilder

    m = OscMessageBuilder("/VMC/Ext/Bone/Pos")
    for a in _bone("Head", unity_quaternion(np.array([0.2, 0.0, 0.0])))[1]:
        m.add_arg(a)
    bone = m.build().dgram
    assert d.feed(bone).passthrough == (bone,)  # a body tracker's stream: unchanged
    d.feed(vmc_bundle(["jawOpen"], [0.1]).dgram)  # now a face sender
    assert d.feed(bone) is None  # held for the next Apply
    f = d.feed(vmc_bundle(["jawOpen"], [0.2]).dgram)
    assert f.pose[0] == pytest.approx(0.2, abs=1e-6)


def test_livelink_stream_comes_out_as_a_cleaned_vmc_head():
    packets = livelink.read_recording(shared("raw_streams", "llv_dao.gesichter"))
    raw = np.array([livelink.decode(p).pose for p in packets])  # (180, 9) rad
    with (
        vmc_peer() as peer,
        _serving(_relay("livelink://127.0.0.1:0", f"vmc://127.0.0.1:{peer.port}")) as relay,
    ):
        client = UDPClient("127.0.0.1", relay.address.port)
        for p in packets:
            before = len(peer.frames)
            client._sock.sendto(p, ("127.0.0.1", relay.address.port))
            assert peer.wait_for(before + 1)
    heads = [a for address, a in peer.other if address == "/VMC/Ext/Bone/Pos" and a[0] == "Head"]
    eyes = [a for address, a in peer.other if address == "/VMC/Ext/Bone/Pos" and a[0] == "LeftEye"]
    assert len(heads) == len(eyes) == len(packets)
    got = unity_angles(np.array([h[4:8] for h in heads]))  # (180, 3) yaw, pitch, roll
    assert np.abs(got - raw[:, :3]).max() < np.radians(1.5)  # the same head ...
    assert _jitter(got) < 0.8 * _jitter(raw[:, :3])  # ... with less jitter
    np.testing.assert_allclose(got[0], raw[0, :3], atol=1e-6)  # the first frame starts it
    assert all(h[1:4] == [0.0, 0.0, 0.0] for h in heads)  # Live Link sends no position


def test_vmc_head_comes_out_as_cleaned_livelink_angles():
    rng = np.random.default_rng(2)
    n = 90
    ypr = np.stack([0.3 * np.sin(np.arange(n) / 20), np.zeros(n), np.zeros(n)], axis=1)
    noisy = ypr + rng.normal(0, 0.01, ypr.shape)
    with (
        raw_receiver() as rx,
        _serving(
            _relay("vmc://127.0.0.1:0", f"livelink://127.0.0.1:{rx.getsockname()[1]}")
        ) as relay,
    ):
        client = UDPClient("127.0.0.1", relay.address.port)
        out = []
        for i in range(n):
            bone = _bone("Head", unity_quaternion(noisy[i]))
            client.send(vmc_bundle(["jawOpen"], [0.3], t=i / 60, extra=[bone]))
            out.append(livelink.decode(rx.recv(65536)))
    pose = np.array([f.pose for f in out])  # (n, 9)
    assert _jitter(pose[:, :3]) < 0.5 * _jitter(noisy)
    assert np.abs(pose[:, :3] - ypr).max() < 0.05
    assert np.isnan(pose[:, 3:]).all()  # no eyes sent: zeros in the packet, read as absent


# -- timecode ------------------------------------------------------------------------------


def _timecodes(frames) -> np.ndarray:
    return np.array([(f.timecode[0], f.timecode[1], f.timecode[2], f.timecode[3]) for f in frames])


def test_relay_record_and_replay_keep_the_trackers_timecode(tmp_path, capsys):
    packets = livelink.read_recording(shared("raw_streams", "llv_dao.gesichter"))
    src = [livelink.decode(p) for p in packets]
    rec = Recorder(tmp_path / "take.csv")
    with raw_receiver() as rx:
        rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        send = f"livelink://127.0.0.1:{rx.getsockname()[1]}"
        with (
            _serving(_relay("livelink://127.0.0.1:0", send, rec)) as relay,
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tracker,
        ):
            out = []
            for p in packets:  # the tracker's packets, one at a time, through the relay
                tracker.sendto(p, ("127.0.0.1", relay.address.port))
                out.append(livelink.decode(rx.recv(65536)))
    np.testing.assert_array_equal(_timecodes(out), _timecodes(src))  # frame, sub, rate
    # replay of the .gesichter recording sends the packets' own timecode too
    with raw_receiver() as rx:
        rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        frames = frames_from_recording(shared("raw_streams", "llv_dao.gesichter"))
        to = parse(f"livelink://127.0.0.1:{rx.getsockname()[1]}", "send")
        assert replay(frames, to, speed=50.0) == 180
        replayed = [livelink.decode(rx.recv(65536)) for _ in range(180)]
    np.testing.assert_array_equal(_timecodes(replayed), _timecodes(src))
    # --record: the take's Timecode column is the tracker's (time of day), not 00:00:00
    take_path, clean_path = rec.save()
    first = src[0].timecode
    day = ((first[0] + first[1]) / 60.0) % 86400
    text = take_path.read_text().splitlines()[1].split(",")[0]
    assert text == livelink_text(day)
    take, cleaned = io.load(take_path), io.load(clean_path)
    np.testing.assert_allclose(take.meta["pose"], [f.pose for f in src], atol=1e-9)  # raw in
    assert np.abs(cleaned.meta["pose"] - take.meta["pose"]).max() > 1e-4  # cleaned out
    # replay of the recorded CSV sends the same timecode again (60 fps frames, mod a day)
    with raw_receiver() as rx:
        rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        url = f"livelink://127.0.0.1:{rx.getsockname()[1]}"
        assert main(["replay", str(take_path), "--send", url, "--speed", "50"]) == 0
        again = [livelink.decode(rx.recv(65536)) for _ in range(180)]
    got = _timecodes(again)
    np.testing.assert_array_equal(got[:, 0], _timecodes(src)[:, 0] % DAY_FRAMES)
    np.testing.assert_allclose(got[:, 1], _timecodes(src)[:, 1], atol=2e-3)  # 1/1000 frame
    assert (got[:, 2:] == [60, 1]).all()


def livelink_text(seconds: float) -> str:
    from faceclean.io.livelink_csv import timecode_text

    return timecode_text(seconds)


def test_a_vmc_recording_takes_the_arrival_time_and_says_so(tmp_path, capsys):
    rec = Recorder(tmp_path / "vmc.csv")
    x = np.full(52, 0.4)
    arrival = 1_700_000_000.25  # s since the epoch
    for i in range(5):
        rec.add(i / 60, x, x, None, None, None, arrival + i / 60)
    take_path, _ = rec.save()
    take = io.load(take_path)
    assert take.meta["pose_names"] == (*POSE, ARRIVAL)  # the app's angles (0), then it
    local = time.localtime(arrival)
    day = local.tm_hour * 3600 + local.tm_min * 60 + local.tm_sec + 0.25
    assert take.meta["timecode_start"] == pytest.approx(day, abs=1e-3)
    np.testing.assert_allclose(take.meta["pose"][:, -1], day + np.arange(5) / 60, atol=1e-6)
    assert main(["info", str(take_path)]) == 0
    assert "arrival time" in capsys.readouterr().out


def test_livelink_encoder_keeps_a_frames_timecode_and_counts_without_one():
    f = Frame(ARKIT52, np.zeros(52), 2.0, timecode=(123456, 0.25, 30, 1))
    g = livelink.decode(livelink.Encoder().encode(f))
    assert g.timecode == (123456, 0.25, 30, 1)
    h = livelink.decode(livelink.Encoder().encode(Frame(ARKIT52, np.zeros(52), 2.0)))
    assert h.timecode == (120, 0.0, 60, 1)


def test_ifacialmocap_head_reaches_livelink_out():
    with (
        raw_receiver() as rx,
        _serving(
            _relay("ifacialmocap://127.0.0.1:0", f"livelink://127.0.0.1:{rx.getsockname()[1]}")
        ) as relay,
    ):
        client = UDPClient("127.0.0.1", relay.address.port)
        client._sock.sendto(b"jawOpen-50|=head#10,20,5,0,0,0|leftEye#1,2,0|rightEye#1,2,0|",
                            ("127.0.0.1", relay.address.port))  # fmt: skip
        f = livelink.decode(rx.recv(65536))
    np.testing.assert_allclose(f.pose, np.radians([20, 10, 5, 2, 1, 0, 2, 1, 0]), atol=1e-6)
    assert POSE[0] == "HeadYaw"


# -- issue 37: a non-finite number never goes out --------------------------------------------


def _floats(datagram: bytes) -> list[float]:
    """Every float argument of a VMC datagram, read by python-osc (the peer's parser)."""
    from pythonosc.osc_bundle import OscBundle
    from pythonosc.osc_message import OscMessage

    def walk(element) -> list[float]:
        if isinstance(element, OscBundle):
            return [v for e in element for v in walk(e)]
        return [a for a in element.params if isinstance(a, float)]

    if OscBundle.dgram_is_bundle(datagram):
        return walk(OscBundle(datagram))
    return walk(OscMessage(datagram))


BAD = (float("nan"), float("inf"), float("-inf"))


@pytest.mark.parametrize("out", ["vmc", "livelink"])
def test_a_non_finite_head_position_is_never_relayed(out):
    """A sender's NaN and +-inf Head *position* (and a NaN body bone, a NaN extra channel):
    nothing NaN or infinite reaches the engine; the Head keeps its last good position."""
    good = (0.0, 0.06, 0.01)
    q = unity_quaternion(np.array([0.2, 0.0, 0.0]))
    with raw_receiver() as rx:
        send = f"{out}://127.0.0.1:{rx.getsockname()[1]}"
        with _serving(_relay("vmc://127.0.0.1:0", send)) as relay:
            tx = UDPClient("127.0.0.1", relay.address.port)
            got = []
            for i in range(12):
                position = good if i < 2 else (BAD[i % 3], 0.06, BAD[(i + 1) % 3])
                hips = ("/VMC/Ext/Bone/Pos", ["Hips", BAD[i % 3], 1.0, 0.0, 0.0, 0.0, 0.0, 1.0])
                extra = [_bone("Head", q, position), hips]
                values = [0.2 + 0.01 * i, BAD[i % 3]]
                tx.send(vmc_bundle(["jawOpen", "Joy"], values, t=1.0 + i / 60, extra=extra))
                got.append(rx.recv(65536))
    assert len(got) == 12
    if out == "livelink":
        floats = np.frombuffer(got[-1][-4 * 61 :], ">f4")
        assert all(np.isfinite(np.frombuffer(d[-4 * 61 :], ">f4")).all() for d in got)
        assert floats[52] == pytest.approx(0.2, abs=1e-3)  # the yaw came through
        return
    for d in got:
        floats = _floats(d)
        assert floats and np.isfinite(floats).all(), floats
    from pythonosc.osc_bundle import OscBundle

    last = [m for m in OscBundle(got[-1]) if m.address == "/VMC/Ext/Bone/Pos"]
    assert [m.params[0] for m in last] == ["Head"]  # the NaN Hips message is left out
    assert tuple(last[0].params[1:4]) == pytest.approx(good)  # held, not (nan, 0.06, inf)
