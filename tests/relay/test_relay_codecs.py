"""Relay codecs: pure bytes <-> frames, against byte literals, python-osc and the real
recorded Live Link packets (../shared/data/raw_streams)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from helpers import shared
from hypothesis import given, settings
from hypothesis import strategies as st
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.relay import ifacialmocap, livelink, osc, parse, vmc
from faceclean.relay.frame import Frame, Malformed


def recording():
    ref = np.load(shared("raw_streams", "llv_dao.npz"))
    return livelink.read_recording(shared("raw_streams", "llv_dao.gesichter")), ref


# -- Live Link Face v6 ---------------------------------------------------------------------

ONE = b"\x3f\x80\x00\x00"  # 1.0f
HALF = b"\x3f\x00\x00\x00"  # 0.5f
LL_PACKET = (
    b"\x06"
    + b"\x00\x00\x00\x03dev"
    + b"\x00\x00\x00\x04face"
    + b"\x00\x00\x00\x78"  # frame 120
    + HALF  # sub-frame 0.5
    + b"\x00\x00\x00\x3c\x00\x00\x00\x01"  # 60/1 fps
    + b"\x3d"  # 61 values
    + ONE  # eyeBlinkLeft
    + b"\x00" * 4 * 16
    + HALF  # jawOpen (index 17)
    + b"\x00" * 4 * 34
    + HALF  # HeadYaw
    + b"\x00" * 4 * 8
)


def test_livelink_decodes_a_byte_literal():
    f = livelink.decode(LL_PACKET)
    assert f.names == ARKIT52 and f.device == "dev" and f.subject == "face"
    assert f.t == pytest.approx(120.5 / 60.0)
    assert f.values[0] == 1.0 and f.values[17] == 0.5
    assert np.count_nonzero(f.values) == 2
    assert f.pose is not None and f.pose[:3].tolist() == [0.5, 0.0, 0.0]
    assert np.isnan(f.pose[3:]).all()  # eyes all exactly 0: not tracked, absent


def test_livelink_encoder_writes_the_same_bytes():
    f = livelink.decode(LL_PACKET)
    assert livelink.Encoder().encode(f) == LL_PACKET


def test_livelink_without_pose_and_with_bad_rate():
    short = LL_PACKET[:32] + b"\x34" + LL_PACKET[33 : 33 + 52 * 4]
    f = livelink.decode(short)
    assert f.pose is None and f.values[17] == 0.5
    zero_rate = LL_PACKET[:24] + b"\x00\x00\x00\x00" + LL_PACKET[28:]
    assert livelink.decode(zero_rate).t is None  # the relay falls back to arrival time


@pytest.mark.parametrize(
    "packet",
    [
        b"",
        b"\x05" + LL_PACKET[1:],  # another protocol version
        LL_PACKET[:-1],  # truncated
        LL_PACKET + b"\x00",  # trailing byte
        LL_PACKET[:32] + b"\x3c" + LL_PACKET[33:],  # count 60 != 61 floats
        b"\x06\xff\xff\xff\xff",  # negative string length
        b"\x06\x00\x00\x00\x03\xff\xfe\xfd" + LL_PACKET[8:],  # device id not UTF-8
        LL_PACKET[:24] + b"\xff\xff\xff\xc4" + LL_PACKET[28:],  # rate -60/1: no rate
    ],
)
def test_livelink_rejects_malformed_packets(packet):
    with pytest.raises(Malformed):
        livelink.decode(packet)


def test_livelink_recording_matches_the_decoded_reference():
    packets, ref = recording()
    frames = [livelink.decode(p) for p in packets]
    assert len(frames) == 180
    np.testing.assert_array_equal(np.array([f.values for f in frames]), ref["weights"])
    np.testing.assert_array_equal(np.array([f.pose for f in frames]), ref["pose"])
    t = np.array([f.t for f in frames])
    numbers = np.round(t * 60.0 - np.array([f.sub for f in map(_sub, packets)])).astype(int)
    np.testing.assert_array_equal(numbers, ref["frame_number"])
    first = ref["frame_number"][0] / float(ref["fps"])
    np.testing.assert_allclose(t - first, ref["time"], atol=1e-9)
    assert [str(n) for n in ref["names"]] == list(frames[0].names)
    # re-encoding gives back the recorded packets byte for byte
    enc = livelink.Encoder()
    assert all(enc.encode(f) == p for f, p in zip(frames, packets, strict=True))


class _sub:  # the sub-frame field of a packet, read independently of the decoder
    def __init__(self, packet: bytes) -> None:
        n = struct.unpack_from(">i", packet, 1)[0]
        m = struct.unpack_from(">i", packet, 5 + n)[0]
        self.sub = struct.unpack_from(">f", packet, 9 + n + m + 4)[0]


# -- OSC and VMC ---------------------------------------------------------------------------

VAL_EYE = b"/VMC/Ext/Blend/Val\x00\x00,sf\x00eyeBlink_L\x00\x00" + HALF  # 40 bytes
VAL_JAW = b"/VMC/Ext/Blend/Val\x00\x00,sf\x00JawOpen\x00" + ONE  # 36 bytes
VAL_VRM = b"/VMC/Ext/Blend/Val\x00\x00,sf\x00Joy\x00" + HALF  # 32 bytes
APPLY = b"/VMC/Ext/Blend/Apply\x00\x00\x00\x00,\x00\x00\x00"  # 28 bytes
ROOT = b"/VMC/Ext/OK\x00,i\x00\x00\x00\x00\x00\x01"  # 20 bytes
TIME = b"/VMC/Ext/T\x00\x00,f\x00\x00" + b"\x40\x20\x00\x00"  # 2.5 s, 20 bytes
VMC_BUNDLE = (
    b"#bundle\x00\x00\x00\x00\x00\x00\x00\x00\x01"
    + b"\x00\x00\x00\x14"
    + ROOT
    + b"\x00\x00\x00\x14"
    + TIME
    + b"\x00\x00\x00\x28"
    + VAL_EYE
    + b"\x00\x00\x00\x24"
    + VAL_JAW
    + b"\x00\x00\x00\x20"
    + VAL_VRM
    + b"\x00\x00\x00\x1c"
    + APPLY
)


def test_vmc_decodes_a_bundle_literal():
    f = vmc.Decoder().feed(VMC_BUNDLE)
    assert f is not None and f.is_face
    assert f.names == ("eyeBlink_L", "JawOpen", "Joy")
    np.testing.assert_array_equal(f.values, [0.5, 1.0, 0.5])
    assert f.t == 2.5
    assert f.passthrough == (ROOT, TIME)  # other addresses, untouched


def test_vmc_loose_messages_make_one_frame_at_apply():
    dec = vmc.Decoder()
    assert dec.feed(VAL_EYE) is None
    assert dec.feed(VAL_JAW) is None
    f = dec.feed(APPLY)
    assert f is not None and f.names == ("eyeBlink_L", "JawOpen")
    assert dec.feed(APPLY) is not None and dec.feed(VAL_VRM) is None  # state was cleared


def test_vmc_datagram_without_blendshapes_is_passthrough_only():
    f = vmc.Decoder().feed(ROOT)
    assert f is not None and not f.is_face and f.passthrough == (ROOT,)
    assert vmc.Encoder().encode(f) == ROOT  # forwarded byte for byte


def test_vmc_encoder_output_reads_back_with_python_osc():
    f = Frame(("eyeBlink_L", "JawOpen", "Joy"), np.array([0.25, 0.75, 1.0]), 3.0, None, (ROOT,))
    data = vmc.Encoder(names="arkit", stamp=True).encode(f)
    assert OscBundle.dgram_is_bundle(data)
    msgs = [(m.address, m.params) for m in OscBundle(data)]
    assert msgs[0] == ("/VMC/Ext/T", [3.0])
    assert msgs[1] == ("/VMC/Ext/OK", [1])
    assert msgs[2:5] == [
        ("/VMC/Ext/Blend/Val", ["eyeBlinkLeft", 0.25]),
        ("/VMC/Ext/Blend/Val", ["jawOpen", 0.75]),
        ("/VMC/Ext/Blend/Val", ["Joy", 1.0]),  # not ARKit: name kept
    ]
    assert msgs[5] == ("/VMC/Ext/Blend/Apply", [])
    assert vmc.Decoder().feed(data).names == ("eyeBlinkLeft", "jawOpen", "Joy")


@pytest.mark.parametrize(("style", "name"), [("pascal", "EyeBlinkLeft"), ("lr", "eyeBlink_L")])
def test_vmc_name_styles(style, name):
    f = Frame(("eyeBlinkLeft",), np.array([0.5]))
    assert vmc.Decoder().feed(vmc.Encoder(names=style).encode(f)).names == (name,)


def test_vmc_reads_python_osc_bundles_with_other_argument_types():
    b = OscBundleBuilder(IMMEDIATELY)
    for name, value in (("mouthSmile_L", 0.5), ("cheekPuff", 1)):  # an int value
        m = OscMessageBuilder("/VMC/Ext/Blend/Val")
        m.add_arg(name)
        m.add_arg(value)
        b.add_content(m.build())
    b.add_content(OscMessageBuilder("/VMC/Ext/Blend/Apply").build())
    f = vmc.Decoder().feed(b.build().dgram)
    assert f.names == ("mouthSmile_L", "cheekPuff") and list(f.values) == [0.5, 1.0]


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"hello",
        b"#bundle\x00",  # no time tag
        VMC_BUNDLE[:-3],  # truncated element
        VMC_BUNDLE[:16] + b"\x00\x00\x00\x03" + VMC_BUNDLE[20:],  # size not a multiple of 4
        b"/VMC/Ext/Blend/Val\x00\x00,ss\x00a\x00\x00\x00b\x00\x00\x00",  # value not a number
        b"/VMC/Ext/Blend/Val\x00\x00,sf\x00eyeBlink_L",  # name not terminated
        b"/VMC/Ext/Blend/Val\x00\x00,sb\x00x\x00\x00\x00\x00\x00\x00\x00",  # blob
    ],
)
def test_vmc_rejects_malformed_datagrams(data):
    dec = vmc.Decoder()
    assert dec.feed(VAL_JAW) is None
    with pytest.raises(Malformed):
        dec.feed(data)
    assert dec.feed(APPLY).names == ("JawOpen",)  # a bad datagram leaves the state alone


def test_vmc_values_without_apply_are_bounded():
    dec = vmc.Decoder()
    with pytest.raises(Malformed):
        for i in range(vmc.MAX_PENDING + 1):
            dec.feed(osc.message("/VMC/Ext/Blend/Val", f"x{i}", 0.5))
    assert dec.feed(APPLY).names == ()  # the pile was dropped


# A sender's usual bundle: stamped, with pose bones and a passthrough message.
def _stream_bundle(values, t=1.0, yaw=0.1):
    """A sender's frame, laid out as vmc.Encoder lays it out, but written here: a sender
    may send NaN (our Encoder never does)."""
    names = ("eyeBlinkLeft", "jawOpen", "Joy", "jawOpen")  # a repeated name: the last wins
    pose = np.array([yaw, -0.2, 0.05, 0.1, 0.0, 0.0, np.nan, np.nan, np.nan])
    vals = [
        osc.message("/VMC/Ext/Blend/Val", n, float(v)) for n, v in zip(names, values, strict=True)
    ]
    head = [osc.message("/VMC/Ext/T", float(t)), ROOT, *vmc._bone_messages(pose, {})]
    return osc.bundle([*head, *vals, osc.message("/VMC/Ext/Blend/Apply")])


def _primed():  # a sender's decoder after two frames: it knows their layout
    dec = vmc.Decoder()
    for _ in range(2):
        dec.feed(_stream_bundle([0.1, 0.2, 0.3, 0.4]))
    return dec


def _seen_faces():  # a decoder that has seen a face (loose messages) but keeps no layout
    dec = vmc.Decoder()
    dec.feed(VAL_JAW)
    dec.feed(APPLY)
    return dec


def _same(a, b):
    assert (a is None) == (b is None)
    if a is None:
        return
    assert a.names == b.names and a.passthrough == b.passthrough and a.t == b.t
    np.testing.assert_array_equal(a.values, b.values)  # NaN where NaN
    assert (a.pose is None) == (b.pose is None)
    if a.pose is not None:
        np.testing.assert_array_equal(a.pose, b.pose)
        assert a.positions == b.positions


def test_vmc_known_layout_reads_each_frame_as_a_full_parse():
    dec = vmc.Decoder()
    dec.feed(_stream_bundle([0.1, 0.2, 0.3, 0.4]))
    assert dec._layout is None  # one frame: no layout gathered yet
    dec = _primed()
    rng = np.random.default_rng(0)
    for i in range(50):
        data = _stream_bundle(rng.uniform(0, 1, 4), t=1.0 + i / 60, yaw=rng.uniform(-1, 1))
        assert dec._layout.read(data) is not None  # read from its floats alone
        _same(dec.feed(data), _seen_faces().feed(data))
    f = dec.feed(_stream_bundle([0.5, 0.6, np.nan, 0.25], t=2.0))
    assert f.names == ("eyeBlinkLeft", "jawOpen", "Joy")
    np.testing.assert_array_equal(f.values, [0.5, 0.25, np.nan])
    assert f.t == 2.0 and ROOT in f.passthrough and abs(f.pose[0] - 0.1) < 1e-6


def test_vmc_known_layout_refuses_what_a_full_parse_refuses():
    dec = _primed()
    with pytest.raises(Malformed, match="packet time"):
        dec.feed(_stream_bundle([0.1, 0.2, 0.3, 0.4], t=float("inf")))
    f = dec.feed(_stream_bundle([np.inf, 0.2, 0.3, 0.4]))  # not finite: NaN, as parsed
    assert np.isnan(f.values[0])
    renamed = _stream_bundle([0.1, 0.2, 0.3, 0.4]).replace(b"Joy", b"Jo\xff")
    with pytest.raises(Malformed, match="UTF-8"):
        dec.feed(renamed)  # another word: parsed in full


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_vmc_known_layout_gives_a_full_parse_on_any_damage(data):
    sent = bytearray(_stream_bundle([0.7, 0.6, 0.5, 0.9], t=3.0, yaw=-0.4))
    for _ in range(data.draw(st.integers(1, 4))):  # bytes changed anywhere
        sent[data.draw(st.integers(0, len(sent) - 1))] = data.draw(st.integers(0, 255))
    if data.draw(st.booleans()):
        sent = sent[: data.draw(st.integers(0, len(sent)))]
    primed, fresh = _primed(), _seen_faces()
    results = []
    for dec in (primed, fresh):
        try:
            results.append(dec.feed(bytes(sent)))
        except Malformed as e:
            results.append(str(e))
    if isinstance(results[0], str) or isinstance(results[1], str):
        assert results[0] == results[1]
    else:
        _same(*results)


def test_a_message_no_parser_reads_is_left_out_of_the_frames_bundle():
    # red team: one flipped byte in an address made the relay's whole output bundle
    # unreadable to python-osc, and the frame's cleaned values with it
    good = _stream_bundle([0.1, 0.2, 0.3, 0.4])
    bad = bytearray(good)
    bad[bad.find(b"/VMC/Ext/Blend/Val") + 9] = 0xFF  # the first Val's address, not UTF-8
    f = vmc.Decoder().feed(bytes(bad))
    assert f.names == ("jawOpen", "Joy") and ROOT in f.passthrough
    out = vmc.Encoder().encode(f)
    assert [m.address for m in OscBundle(out)][-1] == "/VMC/Ext/Blend/Apply"  # it parses


def test_well_formed_takes_every_argument_type_python_osc_writes():
    m = OscMessageBuilder("/VMC/Ext/Root/Pos")
    for value, kind in ((1, "i"), (2.5, "f"), (2.5, "d"), ("x", "s"), (b"abcde", "b"),
                        (2**40, "h"), (True, "T"), (False, "F"), (None, "N"),
                        ((1, 2, 3, 4), "m"), (0x11223344, "r"), ([1, 2.0], None)):  # fmt: skip
        m.add_arg(value, kind) if kind else m.add_arg(value)
    data = m.build().dgram
    assert osc.well_formed(data, 0, len(data))
    for cut in range(len(data) - 1, 0, -4):  # a cut one: some argument runs past the end
        assert not osc.well_formed(data, 0, cut) or cut <= data.find(b",")
    assert not osc.well_formed(b"/a\x00\x00,q\x00\x00", 0, 8)  # an unknown type


# -- iFacialMocap --------------------------------------------------------------------------

IFM = (
    b"mouthSmile_R-25|eyeBlink_L-100|jawOpen-0|"
    b"=head#-21.4,-6.0,-6.6,-0.03,-0.10,-0.65|rightEye#6.0,2.4,0.25|leftEye#6.0,-1.6,-0.17|"
)


def test_ifacialmocap_decodes_percent_values_and_its_head_and_eyes():
    f = ifacialmocap.decode(IFM)
    assert f.names == ("mouthSmile_R", "eyeBlink_L", "jawOpen")
    np.testing.assert_allclose(f.values, [0.25, 1.0, 0.0])
    assert f.t is None
    # rx, ry, rz degrees -> yaw (ry), pitch (rx), roll (rz) radians; head, left, right eye
    want = [-6.0, -21.4, -6.6, -1.6, 6.0, -0.17, 2.4, 6.0, 0.25]
    np.testing.assert_allclose(f.pose, np.radians(want))
    assert ifacialmocap.decode(b"jawOpen-5|").pose is None  # no rotation fields: no pose
    with pytest.raises(Malformed, match="rotation"):
        ifacialmocap.decode(b"jawOpen-5|=head#1,2|")


def test_ifacialmocap_ampersand_variant():
    f = ifacialmocap.decode(b"eyeBlink_R&40|cheekPuff&7.5|")
    np.testing.assert_allclose(f.values, [0.4, 0.075])


@pytest.mark.parametrize("data", [b"", b"\xff\xfe", b"eyeBlink_L|", b"eyeBlink_L-x|", b"|||"])
def test_ifacialmocap_rejects_malformed(data):
    with pytest.raises(Malformed):
        ifacialmocap.decode(data)


# -- URLs ----------------------------------------------------------------------------------


def test_urls_default_to_localhost_and_protocol_ports():
    assert str(parse("vmc://")) == "vmc://127.0.0.1:39539"
    assert str(parse("livelink://:0")) == "livelink://127.0.0.1:0"
    assert parse("vmc://0.0.0.0:39540").host == "0.0.0.0"  # only when asked
    assert parse("ifacialmocap://").port == 49983
    assert parse("vmc://127.0.0.1:9000?names=pascal", "send").options == {"names": "pascal"}


@pytest.mark.parametrize(
    ("url", "role"),
    [
        ("osc://1.2.3.4:5", "listen"),
        ("ifacialmocap://127.0.0.1:49983", "send"),  # input only
        ("vmc://127.0.0.1:0", "send"),
        ("vmc://127.0.0.1:99999", "listen"),
        ("vmc://127.0.0.1:9000/path", "send"),
        ("vmc://127.0.0.1:9000?names=shout", "send"),
        ("vmc://127.0.0.1:9000?names=arkit", "listen"),
    ],
)
def test_bad_urls_are_one_line_errors(url, role):
    with pytest.raises(FacecleanError) as e:
        parse(url, role)
    assert "\n" not in str(e.value)


# -- property: decoders answer any bytes with a frame, None, or Malformed ------------------


def _decoders():
    return [vmc.Decoder(), livelink.Decoder(), ifacialmocap.Decoder()]


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=400))
def test_decoders_never_raise_anything_but_malformed(data):
    for dec in _decoders():
        try:
            f = dec.feed(data)
        except Malformed:
            continue
        assert f is None or len(f.names) == len(f.values)


@settings(max_examples=150, deadline=None)
@given(st.integers(0, len(VMC_BUNDLE) - 1), st.integers(0, len(LL_PACKET) - 1))
def test_truncated_packets_are_malformed_or_partial(cut_vmc, cut_ll):
    with pytest.raises(Malformed):
        livelink.decode(LL_PACKET[:cut_ll])
    try:
        f = vmc.Decoder().feed(VMC_BUNDLE[:cut_vmc])
    except Malformed:
        return
    assert f is None or len(f.names) <= 3  # cut at an element boundary: fewer messages


def test_readme_tells_a_wifi_phone_user_to_listen_on_0000_with_the_warning():
    # issue 19: only docs/RELAY.md said that a phone on Wi-Fi needs --listen 0.0.0.0
    import re

    from helpers import REPO

    from faceclean.relay.url import parse as parse_url

    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text.split("### A phone on Wi-Fi", 1)[1].split("\n## ", 1)[0]
    command = re.search(r"faceclean relay --listen (\S+) --send (\S+)", section)
    assert command, section
    listen = parse_url(command.group(1), "listen")
    assert listen.host == "0.0.0.0" and listen.port == 11112
    assert parse_url(command.group(2), "send").host == "127.0.0.1"
    assert "**Warning:**" in section and "anyone" in section and "foreign" in section


@pytest.mark.parametrize(
    "url,role",
    [("vmc://127.0.0.1:0?names=arkit", "listen"), ("livelink://127.0.0.1:9?names=arkit", "send")],
)
def test_names_on_the_wrong_url_says_where_it_belongs(url, role):
    # third red team: "unknown option 'names'" misled, names being a vmc send option
    from faceclean.relay.url import parse as parse_url

    with pytest.raises(FacecleanError, match=r"\?names= is for a vmc:// --send URL"):
        parse_url(url, role)
