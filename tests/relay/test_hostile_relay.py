"""Issue 14, class 1: one sender's datagrams neither kill the relay nor grow it.

Real sockets over loopback; the relay is driven in this thread (``_drain`` after the
datagrams are queued, so every count is exact) or run as the `faceclean relay` command.
"""

from __future__ import annotations

import contextlib
import socket
import struct

import numpy as np
import pytest

from faceclean import filters
from faceclean.channels import ARKIT52
from faceclean.cli import main
from faceclean.relay import Relay, bounds, livelink, osc, parse, vmc
from faceclean.relay.frame import Frame, Malformed


@contextlib.contextmanager
def relay_to(send_scheme: str = "vmc", listen_scheme: str = "vmc", clock=None):
    """(relay, receiver socket, sender factory): a relay that is not running; call drain().
    ``clock`` (s) replaces time.monotonic for arrival times."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    relay = Relay(
        parse(f"{listen_scheme}://127.0.0.1:0"),
        parse(f"{send_scheme}://127.0.0.1:{rx.getsockname()[1]}", "send"),
        filters.make("ema"),
        **({} if clock is None else {"clock": clock}),
    )
    senders: list[socket.socket] = []

    def sender() -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.connect(("127.0.0.1", relay.address.port))
        senders.append(s)
        return s

    try:
        yield relay, rx, sender
    finally:
        relay.close()
        rx.close()
        for s in senders:
            s.close()


def drain(relay: Relay) -> None:
    before = -1
    while relay.stats.datagrams != before:
        before = relay.stats.datagrams
        relay._drain()


def received(rx: socket.socket) -> list[bytes]:
    out = []
    with contextlib.suppress(BlockingIOError):
        while True:
            out.append(rx.recv(65536))
    return out


def time_d(t: float) -> bytes:
    return osc.pad(b"/VMC/Ext/T") + osc.pad(b",d") + struct.pack(">d", t)


def frame_with_time(t_message: bytes, value: float = 0.5) -> bytes:
    return osc.bundle(
        [
            t_message,
            osc.message("/VMC/Ext/Blend/Val", "jawOpen", value),
            osc.message(vmc.APPLY.decode()),
        ]
    )


@pytest.mark.parametrize("t", [1e308, -1e300, float("nan"), float("inf"), 1e10])
def test_absurd_vmc_time_to_livelink_is_dropped_and_the_relay_goes_on(t):
    # today: /VMC/Ext/T 1e308 relayed to livelink:// raised OverflowError in the encoder
    with relay_to("livelink") as (relay, rx, sender):
        tx = sender()
        tx.send(frame_with_time(time_d(1.0)))
        tx.send(frame_with_time(time_d(t)))
        drain(relay)
        tx.send(frame_with_time(time_d(1.1), 0.25))
        drain(relay)
        packets = [livelink.decode(p) for p in received(rx)]
    assert relay.stats.malformed == 1
    assert len(packets) == 2 and relay.stats.frames_out == 2
    assert all(abs(p.t - want) < 0.02 for p, want in zip(packets, (1.0, 1.1), strict=True))


@pytest.mark.parametrize("t", [1e308, -1e308, 2.0**70, float("inf"), float("nan")])
def test_livelink_encoder_never_overflows(t):
    data = livelink.Encoder().encode(Frame(ARKIT52, np.zeros(52), t))
    assert livelink.decode(data).values.shape == (52,)


def test_values_beyond_float32_are_held_not_overflowed():
    val = osc.pad(b"/VMC/Ext/Blend/Val") + osc.pad(b",sd") + osc.pad(b"jawOpen")
    frame = vmc.Decoder().feed(
        osc.bundle([val + struct.pack(">d", 1e308), osc.message(vmc.APPLY.decode())])
    )
    assert np.isnan(frame.values).all()  # a NaN cell: the cleaner holds it
    with np.errstate(all="raise"):  # and nothing on the way out warns
        vmc.Encoder().encode(frame)


def test_ever_new_long_names_and_senders_stay_within_the_bounds():
    # today: ever-new names and subjects grew the relay without bound (+1.5 GB in 5 s)
    with relay_to("livelink") as (relay, rx, sender):
        for batch in range(40):
            tx = sender()  # a new source address every batch
            for k in range(100):
                n = batch * 100 + k
                names = [f"n{n}_{j}_" + "x" * 100 for j in range(3)]
                tx.send(vmc.Encoder().encode(Frame(tuple(names), np.full(3, 0.5), None)))
                tx.send(osc.message("/VMC/Ext/Blend/Val", f"loose{n}" + "y" * 100, 0.5))
                subject = f"s{n}".encode() * 10
                tx.send(
                    b"\x06"
                    + struct.pack(">i", 1)
                    + b"d"
                    + struct.pack(">i", len(subject))
                    + subject
                )
            drain(relay)
            tx.close()
        received(rx)
    assert relay.stats.datagrams == 12_000
    assert len(relay._decoders) <= bounds.MAX_SENDERS
    assert len(relay._columns) <= bounds.MAX_CACHE
    assert len(relay.encoder._index) <= bounds.MAX_CACHE
    assert len(relay.encoder._heads) <= bounds.MAX_CACHE


@pytest.mark.parametrize(
    "datagram",
    [
        osc.message("/VMC/Ext/Blend/Val", "x" * (bounds.MAX_NAME_BYTES + 1), 0.5),
        vmc.Encoder().encode(Frame(tuple(f"c{i}" for i in range(300)), np.zeros(300), None)),
        b"\x06" + struct.pack(">i", 200) + b"d" * 200 + struct.pack(">i", 0),
    ],
    ids=["long-name", "300-names", "long-device"],
)
def test_oversized_names_and_frames_are_malformed(datagram):
    decoder = livelink.Decoder() if datagram[0] == 6 else vmc.Decoder()
    with pytest.raises(Malformed):
        decoder.feed(datagram)


def test_pending_bytes_per_sender_are_bounded():
    d = vmc.Decoder()
    with pytest.raises(Malformed):  # 600 loose values of 120-byte names: over 64 KiB
        for i in range(600):
            d.feed(osc.message("/VMC/Ext/Blend/Val", f"{i:04d}" + "z" * 116, 0.5))
    assert d._bytes <= bounds.MAX_PENDING_BYTES and len(d._vals) < 600


def test_a_second_sender_neither_mixes_values_in_nor_takes_over():
    # loose values of a hostile sender no longer end up in the good sender's frames
    with relay_to() as (relay, rx, sender):
        good, bad = sender(), sender()
        for i in range(20):
            good.send(vmc.Encoder(stamp=True).encode(Frame(("jawOpen",), np.zeros(1), i / 60)))
            bad.send(osc.message("/VMC/Ext/Blend/Val", f"junk{i}", 1.0))  # never applied
            bad.send(vmc.Encoder().encode(Frame(("jawOpen",), np.ones(1), 100.0 + i)))
            drain(relay)
        good.send(vmc.Encoder(stamp=True).encode(Frame(("jawOpen",), np.zeros(1), 1.0)))
        drain(relay)
        frames = [vmc.Decoder().feed(p) for p in received(rx)]
    assert len(frames) == 21 and relay.stats.foreign == 20
    assert all(f.names == ("jawOpen",) and f.values[0] == 0.0 for f in frames)


class Clock:
    """Arrival time s that the test moves on (the relay reads it per face frame)."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _stamped(value: float, t: float) -> bytes:
    return vmc.Encoder(stamp=True).encode(Frame(("jawOpen",), np.full(1, value), t))


def test_a_stray_frame_after_a_silence_never_takes_the_stream():
    clock = Clock()
    with relay_to(clock=clock) as (relay, rx, sender):
        good, other = sender(), sender()
        for i in range(10):
            good.send(_stamped(0.0, i / 60))
            drain(relay)
            clock.now += 1 / 60
        clock.now += 5.0  # the good sender pauses far longer than HANDOVER
        other.send(_stamped(1.0, 50.0))  # one frame from elsewhere
        drain(relay)
        clock.now += 0.5
        good.send(_stamped(0.0, 10 / 60))  # it resumes: still the face followed
        drain(relay)
        frames = [vmc.Decoder().feed(p) for p in received(rx)]
    assert relay.stats.foreign == 1 and len(frames) == 11
    assert all(f.values[0] == 0.0 for f in frames)


def test_a_tracker_restarted_on_a_new_port_takes_over_after_the_silence():
    from faceclean.relay.loop import CLAIM, HANDOVER

    clock = Clock()
    with relay_to(clock=clock) as (relay, rx, sender):
        old, new = sender(), sender()
        old.send(_stamped(0.0, 0.0))
        drain(relay)
        assert len(received(rx)) == 1
        last_old = clock.now
        clock.now += 0.5  # the app restarts: the new port streams at 60 fps from here
        taken, frames = None, []
        for i in range(120):
            new.send(_stamped(1.0, i / 60))
            drain(relay)
            got = [vmc.Decoder().feed(p) for p in received(rx)]
            if taken is None and got:
                taken = clock.now
            frames += got
            clock.now += 1 / 60
    assert taken is not None and taken - last_old >= HANDOVER
    assert taken - last_old < HANDOVER + CLAIM  # it streamed long enough during the silence
    assert relay.stats.foreign == round((taken - last_old - 0.5) * 60)
    assert len(frames) + relay.stats.foreign == 120 and all(f.values[0] == 1.0 for f in frames)


def test_senders_on_ever_new_ports_do_not_keep_the_stream_from_a_resumed_tracker():
    """The soak's attack: a hostile face stream whose source port changes every 0.5 s
    takes the stream during the good sender's 2 s silence (as a restarted tracker would),
    but once the good sender streams again it wins the stream back and keeps it."""
    from faceclean.relay.loop import CLAIM, HANDOVER

    clock = Clock()
    with relay_to(clock=clock) as (relay, rx, sender):
        good = sender()
        hostile = [sender() for _ in range(12)]
        good_t, relayed, resumed = 0.0, [], None
        for i in range(6 * 60):  # 6 s at 60 fps
            now = i / 60
            if not 1.0 <= now < 3.0:  # the good sender is silent from 1 s to 3 s
                good.send(_stamped(0.0, good_t))
                good_t += 1 / 60
                resumed = resumed if now < 3.0 or resumed is not None else now
            if i % 2 == 0:  # 30 face frames a second from a port that changes every 0.5 s
                hostile[int(now / 0.5)].send(_stamped(1.0, 1000.0 + now))
            drain(relay)
            relayed += [(now, vmc.Decoder().feed(p).values[0]) for p in received(rx)]
            clock.now += 1 / 60
    hostile_out = [t for t, v in relayed if v == 1.0]
    assert hostile_out and min(hostile_out) >= 2.0  # taken only after 1 s of silence
    back = min(t for t, v in relayed if v == 0.0 and t >= resumed)
    assert back - resumed < HANDOVER + 0.5 + CLAIM  # the last hostile port's 0.5 s + 1 s
    assert all(v == 0.0 for t, v in relayed if t >= back)  # and it keeps it


def test_own_output_looping_back_is_dropped():
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    port = rx.getsockname()[1]
    rx.close()
    # listen on every interface, send to loopback on the same port: refused at start
    with pytest.raises(Exception, match="listens on"):
        Relay(
            parse(f"vmc://0.0.0.0:{port}"),
            parse(f"vmc://127.0.0.1:{port}", "send"),
            filters.make("ema"),
        )


@pytest.mark.parametrize(
    "listen, send",
    [("vmc://127.0.0.1:{p}", "vmc://127.0.0.1:{p}"), ("vmc://0.0.0.0:{p}", "vmc://127.0.0.1:{p}"),
     ("livelink://:{p}", "livelink://localhost:{p}")],
)  # fmt: skip
def test_listen_equal_to_send_is_refused(listen, send, capsys):
    # today: one datagram became a feedback storm
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        p = s.getsockname()[1]
    assert (
        main(
            ["relay", "--listen", listen.format(p=p), "--send", send.format(p=p), "--method", "ema"]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "listens on" in err[0]


@pytest.mark.parametrize("stats", ["inf", "nan", "1e-300", "1e300", "-1", "0"])
def test_absurd_stats_period_is_refused(stats, capsys):
    # today: --stats inf started and then died (OverflowError in select)
    assert main(["relay", "--listen", "vmc://:0", "--send", "vmc://:9", "--stats", stats]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("faceclean: --stats must be between")
