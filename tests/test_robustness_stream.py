"""docs/ROBUSTNESS.md, streams: out-of-order and repeated frames, long silences, NaN and
absurd values change nothing they should not, for every stream cleaner and the relay."""

from __future__ import annotations

import contextlib
import socket
import threading

import numpy as np
import pytest

from faceclean.channels import ARKIT52
from faceclean.filters.base import StreamCleaner
from faceclean.relay import Relay, livelink, parse
from faceclean.relay.frame import Frame
from faceclean.resolve import resolve

M = 6
NAMES = ARKIT52[:M]
WAIT = 5.0  # s; the most one datagram may take on loopback before the test gives up


def _lstm() -> StreamCleaner:
    from faceclean.learned.checkpoint import LSTMWeights
    from faceclean.learned.lstm import Learned

    return Learned(weights=LSTMWeights.random(NAMES, hidden=16, layers=2, seed=1), names=NAMES)


MAKERS = {m: (lambda m=m: resolve(m).build(NAMES)) for m in ("ema", "one-euro", "kalman")}
MAKERS["lstm"] = _lstm


def _frames(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(n,) times s at a jittered 60 fps and (n, M) weights in [0, 1]."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.8, 1.2, n)) / 60.0
    x = np.clip(0.5 + np.cumsum(rng.normal(0, 0.03, (n, M)), axis=0), 0, 1)
    return t, x


def _run(cleaner: StreamCleaner, t, x) -> np.ndarray:
    cleaner.reset()
    return np.array([cleaner.step(xi, ti) for ti, xi in zip(t, x, strict=True)])


@pytest.mark.parametrize("method", MAKERS)
def test_hostile_frames_change_nothing_after_them(method):
    """Duplicates, late frames, all-NaN frames and NaN times: the output repeats the last
    one and every later output is what it would have been without them."""
    t, x = _frames(60)
    ref = _run(MAKERS[method](), t, x)
    c = MAKERS[method]()
    c.reset()
    rng = np.random.default_rng(1)
    for i in range(len(t)):
        y = c.step(x[i], t[i])
        np.testing.assert_array_equal(y, ref[i])
        if i % 5 == 4:  # after every fifth frame, a burst of garbage
            for bad_t, bad_x in [
                (t[i], rng.random(M)),  # duplicate time
                (t[i] - 0.05, rng.random(M)),  # late (out of order)
                (t[i] + 0.001, np.full(M, np.nan)),  # tracking loss
                (float("nan"), rng.random(M)),  # no time
                (t[i] + 0.002, np.full(M, np.inf)),  # nothing finite
            ]:
                np.testing.assert_array_equal(c.step(bad_x, bad_t), ref[i])


@pytest.mark.parametrize("method", MAKERS)
def test_long_silence_restarts_exactly_at_the_face(method):
    t, x = _frames(80)
    t[40:] += 30.0  # 30 s of silence, then the face comes back
    out = _run(MAKERS[method](), t, x)
    np.testing.assert_array_equal(out[40], x[40])  # no jump, no drift: the input itself
    fresh = _run(MAKERS[method](), t[40:], x[40:])
    np.testing.assert_array_equal(out[40:], fresh)  # as if the stream had just started


@pytest.mark.parametrize("method", MAKERS)
def test_nan_and_absurd_cells_hold_their_channel(method):
    t, x = _frames(60)
    bad = x.copy()
    bad[20:30, 1] = np.nan
    bad[25, 2] = np.inf
    bad[26, 3] = -1e300
    bad[27, 4] = 5e6  # beyond MAX_ABS: a glitch, not a weight
    out = _run(MAKERS[method](), t, bad)
    assert np.isfinite(out).all()
    assert out.min() > -0.5 and out.max() < 1.5
    clean = _run(MAKERS[method](), t, x)
    np.testing.assert_array_equal(out[:20], clean[:20])  # causal: nothing before changes
    if method != "lstm":  # per-channel filters: an untouched channel is unaffected
        np.testing.assert_array_equal(out[:, 5], clean[:, 5])


@pytest.mark.parametrize("method", MAKERS)
def test_any_time_step_gives_finite_output(method):
    rng = np.random.default_rng(4)
    dt = 10.0 ** rng.uniform(-9, 3, 400)  # from a nanosecond to twenty minutes
    t = np.cumsum(dt)
    x = rng.random((400, M))
    out = _run(MAKERS[method](), t, x)
    assert np.isfinite(out).all() and np.abs(out).max() < 10


@pytest.mark.parametrize("method", MAKERS)
def test_streams_are_independent(method):
    """S streams stepped together: garbage in one never reaches the others."""
    t, x = _frames(50)
    ref = _run(MAKERS[method](), t, x)
    c = MAKERS[method]()
    c.reset()
    for i in range(len(t)):
        frames = np.stack([x[i], x[i], x[i]])  # (3, M)
        ts = np.array([t[i], t[i], t[i]])
        if i % 7 == 3:  # stream 1: NaN frame; stream 2: a time going backwards
            frames[1] = np.nan
            ts[2] = t[i] - 1.0
        y = c.step(frames, ts)
        np.testing.assert_array_equal(y[0], ref[i])
        assert np.isfinite(y).all()


# -- the relay -----------------------------------------------------------------------------


@contextlib.contextmanager
def _udp(timeout: float = WAIT):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(timeout)
    try:
        yield s
    finally:
        s.close()


def _packet(t: float, x: np.ndarray) -> bytes:
    return livelink.Encoder().encode(Frame(ARKIT52, x, t))


def test_relay_sends_only_to_its_send_address_and_binds_localhost():
    """A hostile mix in; clean frames out to the send address only: never back to the
    sender, never to anyone else, and the counters account for every datagram."""
    with _udp() as target, _udp() as sender, _udp() as bystander:
        listen, send = parse("livelink://:0"), parse(f"livelink://:{target.getsockname()[1]}")
        assert listen.host == "127.0.0.1" and send.host == "127.0.0.1"
        relay = Relay(listen, send, resolve("one-euro").build())
        thread = threading.Thread(target=relay.run, daemon=True)
        thread.start()
        try:
            assert relay.address.host == "127.0.0.1"
            to = ("127.0.0.1", relay.address.port)
            x = np.full(52, 0.25)
            good = _packet(10.0, x)
            hostile = [
                b"",
                b"\x06",
                good[:40],  # truncated real packet
                good[:-1],
                b"\x06" + b"\xff" * (len(good) - 1),
                _packet(9.99, np.full(52, 0.9)),  # late
                _packet(10.0, np.full(52, 0.9)),  # duplicate
            ]
            received = []
            sender.sendto(good, to)
            received.append(target.recv(65535))
            for h in hostile:
                sender.sendto(h, to)
            sender.sendto(_packet(10.0 + 1 / 60, x), to)  # the next good frame
            received.append(target.recv(65535))
            stats = relay.stats
            assert stats.frames_out == 2 and stats.malformed == 5 and stats.out_of_order == 2
            assert stats.datagrams == 2 + len(hostile)
            for data in received:
                np.testing.assert_allclose(livelink.decode(data).values, 0.25, atol=1e-6)
            # the relay sent in order; both our frames arrived, so nothing else is pending
            for s in (sender, bystander):
                s.setblocking(False)
                with pytest.raises(BlockingIOError):
                    s.recv(65535)
        finally:
            relay.stop()
            thread.join(WAIT)
            relay.close()
        assert not thread.is_alive()
