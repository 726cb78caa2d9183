"""The tuning page's server over real loopback sockets: the token, the Host and Origin
checks, only its own files, bounded messages, the CLI's refusals (no browser here:
tests/ui/test_ui_page.py drives Chromium)."""

from __future__ import annotations

import contextlib
import http.client
import json

import numpy as np
import pytest

pytest.importorskip("websockets")
from websockets.exceptions import ConnectionClosed, InvalidStatus  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

from faceclean.animation import Animation  # noqa: E402
from faceclean.cli import main  # noqa: E402
from faceclean.io import save  # noqa: E402
from faceclean.ui.offline import Offline  # noqa: E402
from faceclean.ui.server import MAX_MESSAGE, Server  # noqa: E402
from faceclean.ui.tuning import Tuning  # noqa: E402


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ui")
    t = np.arange(120) / 60.0
    x = 0.4 + 0.3 * np.sin(2 * np.pi * t[:, None] + np.arange(52)) / 2
    path = folder / "take.csv"
    save(Animation.from_arkit(t, x), path, fmt="csv")
    return path


@pytest.fixture(scope="module")
def server(take):
    with Server(Offline(str(take), Tuning("one-euro"))) as s:
        yield s


def _get(server, target: str, headers: dict | None = None) -> tuple[int, dict, bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    conn.putrequest("GET", target, skip_host=True, skip_accept_encoding=True)
    for k, v in {"Host": f"127.0.0.1:{server.port}", **(headers or {})}.items():
        conn.putheader(k, v)
    conn.endheaders()
    r = conn.getresponse()
    out = r.status, dict(r.getheaders()), r.read()
    conn.close()
    return out


def test_the_page_needs_the_token_and_sets_it_as_a_strict_cookie(server):
    assert _get(server, "/")[0] == 403
    assert _get(server, "/?token=wrong")[0] == 403
    assert _get(server, "/ui.js")[0] == 403  # every file, not only the page
    status, headers, body = _get(server, f"/?token={server.token}")
    assert status == 200 and b'<script type="module" src="/ui.js">' in body
    cookie = headers["Set-Cookie"]
    assert cookie.startswith(f"{server.cookie}={server.token};")
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    assert "default-src 'none'" in headers["Content-Security-Policy"]
    status, _, body = _get(server, "/ui.js", {"Cookie": f"{server.cookie}={server.token}"})
    assert status == 200 and b"faceclean tuning page" in body
    assert _get(server, "/ui.js", {"Cookie": f"{server.cookie}=x{server.token}"})[0] == 403
    assert _get(server, "/mesh.json")[0] == 403
    status, headers, body = _get(server, f"/mesh.json?token={server.token}")
    assert status == 200 and headers["Content-Type"] == "application/json"
    assert len(json.loads(body)["targets"]) == 52  # the face, beside the live channel


def test_the_pages_script_modules_are_all_served_and_each_is_small(server):
    """ui.js and every module it imports, by the import lines the browser reads: each
    served (the same cookie), each a file in static/, none over ~300 lines."""
    import re

    from faceclean.ui.server import SCRIPTS, STATIC

    assert sorted(SCRIPTS) == sorted(p.name for p in STATIC.glob("*.js"))
    cookie = {"Cookie": f"{server.cookie}={server.token}"}
    seen, todo = set(), ["ui.js"]
    while todo:
        name = todo.pop()
        status, headers, body = _get(server, f"/{name}", cookie)
        assert status == 200 and headers["Content-Type"].startswith("text/javascript"), name
        assert body == (STATIC / name).read_bytes() and len(body.splitlines()) <= 300, name
        seen.add(name)
        found = re.findall(rb'^import [^;]*? from "/([\w.]+\.js)";$', body, re.M)
        todo += [m.decode() for m in found if m.decode() not in seen]
    assert seen == set(SCRIPTS)  # every module reached from the page, none left over


def test_another_host_or_another_site_is_refused_even_with_the_token(server):
    ok = f"/?token={server.token}"
    assert _get(server, ok, {"Host": f"evil.example:{server.port}"})[0] == 403  # DNS rebinding
    assert _get(server, ok, {"Host": f"localhost:{server.port}"})[0] == 200
    assert _get(server, ok, {"Origin": "http://evil.example"})[0] == 403  # CSRF
    assert _get(server, ok, {"Sec-Fetch-Site": "cross-site"})[0] == 403
    assert _get(server, ok, {"Origin": f"http://127.0.0.1:{server.port}"})[0] == 200


@pytest.mark.parametrize(
    "target",
    [
        "/../setup.py",
        "/%2e%2e/%2e%2e/pyproject.toml",
        "/static/ui.js",
        "/ui/../tuning.py",
        "/three/../package.json",
        "/three/three.module.js/../../../../etc/passwd",
        "//etc/passwd",
        "/tuning.py",
    ],
)
def test_only_the_pages_own_files_are_served(server, target):
    sep = "&" if "?" in target else "?"
    status, _, body = _get(server, f"{target}{sep}token={server.token}")
    assert status == 404 and b"not a file of the tuning page" in body


def _uri(server, token: str | None = None) -> str:
    q = "" if token is None else f"?token={token}"
    return f"ws://127.0.0.1:{server.port}/live{q}"


def test_the_live_channel_needs_the_token_and_this_origin(server):
    with pytest.raises(InvalidStatus, match="403"):
        connect(_uri(server)).close()
    with pytest.raises(InvalidStatus, match="403"):
        connect(_uri(server, server.token), origin="http://evil.example").close()
    origin = f"http://127.0.0.1:{server.port}"
    with connect(_uri(server, server.token), origin=origin, max_size=None) as ws:
        hello = json.loads(ws.recv(timeout=10))
        assert hello["type"] == "hello" and hello["mode"] == "offline"
        assert hello["state"]["method"] == "one-euro" and len(hello["channels"]) == 52


@contextlib.contextmanager
def _open(server):
    with connect(_uri(server, server.token), max_size=None) as ws:
        while True:  # hello, then the take's arrays (binary), until the first cleaned take
            m = ws.recv(timeout=30)
            if isinstance(m, bytes) and b'"cleaned"' in m[:200]:
                break
        yield ws


def _reply(ws) -> dict:
    while True:
        m = ws.recv(timeout=30)
        if isinstance(m, str):
            return json.loads(m)


def test_bad_values_get_the_clis_own_one_line_refusal(server, take, tmp_path, capsys):
    for item in ("min_cutof=2", "eyes.gain=abc", "jawOpen.clamp=0.9,0.1", "nobody.beta=1"):
        code = main(["clean", str(take), "-o", str(tmp_path / "o.csv"), "--method", "one-euro",
                     "--set", item])  # fmt: skip
        cli = capsys.readouterr().err.strip()
        assert code == 2 and cli.count("\n") == 0
        with _open(server) as ws:
            ws.send(json.dumps({"type": "set", "words": "one-euro", "items": [item], "seq": 7}))
            got = _reply(ws)
        assert got == {"type": "error", "message": cli, "for": "set", "seq": 7}
    with _open(server) as ws:  # and the page's state did not change
        ws.send(json.dumps({"type": "set", "words": "one-euro", "items": [], "seq": 8}))
        assert _reply(ws)["type"] == "state"


def test_messages_are_bounded_and_checked(server):
    with _open(server) as ws:
        ws.send(json.dumps({"type": "set", "items": ["min_cutoff=1"] * 300}))
        assert "at most 256" in _reply(ws)["message"]
        ws.send(json.dumps({"type": "view", "t0": "x"}))
        assert _reply(ws)["message"] == "faceclean: t0: expected a number"
        ws.send("[1, 2]")
        assert _reply(ws)["message"] == "faceclean: a message is an object"
        ws.send('{"type": "set", "items": [NaN]}')
        assert "not valid JSON" in _reply(ws)["message"]
        ws.send(json.dumps({"type": "shutdown"}))
        assert "unknown message 'shutdown'" in _reply(ws)["message"]
        ws.send("x" * (MAX_MESSAGE + 1))
        with pytest.raises(ConnectionClosed):
            _reply(ws)
        assert ws.close_code == 1009  # message too big


# -- issue 37: never a 500, never "internal error", never a refused state ----------------------


def _twice(server, header: str) -> tuple[int, bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    conn.putrequest("GET", f"/?token={server.token}", skip_host=True, skip_accept_encoding=True)
    conn.putheader("Host", f"127.0.0.1:{server.port}")
    conn.putheader(header, f"127.0.0.1:{server.port}" if header == "Host" else "x")
    conn.endheaders()
    r = conn.getresponse()
    out = r.status, r.read()
    conn.close()
    return out


@pytest.mark.parametrize("header", ["Host", "Origin", "Sec-Fetch-Site"])
def test_a_header_given_twice_is_refused_not_a_500(server, header):
    status, body = _twice(server, header)
    assert status in (400, 403), (status, body)
    assert body.startswith(b"faceclean ui: ") and body.count(b"\n") == 1
    assert _get(server, f"/?token={server.token}")[0] == 200  # and the page lives


def _said(ws, seq: int) -> dict:
    """The reply to the message numbered ``seq`` (states of others' changes skipped)."""
    while True:
        m = _reply(ws)
        if m.get("seq") == seq and m["type"] in ("error", "saved", "state", "exported"):
            return m


@pytest.mark.parametrize(
    "message",
    [
        {"type": "save", "what": "preset", "path": "{d}/p\ud800.json"},
        {"type": "save", "what": "levels", "path": "{d}/l\udcff.json"},
        {"type": "export", "path": "{d}/t\ud800.csv"},
        {"type": "load", "what": "levels", "path": "/proc/self/mem"},
        {"type": "load", "what": "preset", "path": "/proc/self/mem"},
        {"type": "load", "what": "levels", "path": "/proc/self/status"},
        {"type": "load", "what": "levels", "path": "/sys/kernel/mm/transparent_hugepage/enabled"},
    ],
)
def test_hostile_paths_get_one_line_never_an_internal_error(server, tmp_path, message):
    m = {k: v.replace("{d}", str(tmp_path)) for k, v in message.items()}
    with _open(server) as ws:
        ws.send(json.dumps({**m, "seq": 21}))  # ASCII JSON: "\ud800" stays an escape
        got = _said(ws, 21)
    assert got["type"] == "error" and got["for"] == m["type"], got
    text = got["message"]
    assert text.startswith("faceclean: ") and "\n" not in text
    assert "internal error" not in text and "Errno" not in text, text
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_a_refused_setting_leaves_the_state_and_is_never_saved(server, take, tmp_path, capsys):
    """Kalman r=1e300 turns the take into NaN: refused for the "set" that asked, the
    state stays, and a later save writes the state that is, which the CLI loads."""
    with _open(server) as ws:
        ws.send(json.dumps({"type": "set", "words": "kalman", "items": ["q=0.5"], "seq": 30}))
        before = _said(ws, 30)
        assert before["type"] == "state" and before["items"] == ["q=0.5"]
        ws.send(json.dumps({"type": "set", "words": "kalman", "items": ["r=1e300"], "seq": 31}))
        got = _said(ws, 31)
        assert got["type"] == "error" and got["for"] == "set", got
        assert "not finite" in got["message"] and "\n" not in got["message"]
        preset = tmp_path / "p.json"
        ws.send(json.dumps({"type": "save", "what": "preset", "path": str(preset), "seq": 32}))
        state = _said(ws, 32)  # the state first, so a page reading the note has its command
        assert state["type"] == "state" and state["items"] == ["q=0.5"], state
        saved = _said(ws, 32)
        assert saved["type"] == "saved", saved
    with connect(_uri(server, server.token), max_size=None) as ws:  # a page opened now
        state = json.loads(ws.recv(timeout=10))["state"]
    assert state["items"] == ["q=0.5"] and "1e300" not in state["command"]
    assert "1e300" not in preset.read_text() and "1e+300" not in preset.read_text()
    out = tmp_path / "o.csv"
    assert main(["clean", str(take), "-o", str(out), "--preset", str(preset)]) == 0, (
        capsys.readouterr().err
    )
    with _open(server) as ws:  # back to the module's state for the other tests
        ws.send(json.dumps({"type": "set", "words": "one-euro", "items": [], "seq": 33}))
        assert _said(ws, 33)["type"] == "state"


def test_page_messages_are_strict_json_and_binary_has_no_inf():
    from faceclean.ui.offline import packet
    from faceclean.ui.server import Client

    sent = []

    class Connection:
        def send(self, data):
            sent.append(data)

    Client(Connection()).send({"type": "frames", "x": [float("inf"), float("nan"), 1.0]})
    assert json.loads(sent[0], parse_constant=lambda c: 1 / 0)["x"] == [None, None, 1.0]
    values = np.full((2, 52), 0.5)
    values[0, :3] = [np.inf, -np.inf, 1e300]
    data = packet("cleaned", 1, 0, values)
    head = int.from_bytes(data[:4], "little")
    floats = np.frombuffer(data[4 + head :], "<f4").reshape(2, 52)
    assert not np.isinf(floats).any() and np.isnan(floats[0, :3]).all()
    assert (floats[1] == 0.5).all()


def test_the_guided_panel_refuses_in_one_line_and_a_short_take_is_said(server):
    """The guided calibration's messages (ui/guided.py): each refusal is one line, and a
    take too short for the script gets the fit's own reason, nothing applied."""
    with _open(server) as ws:
        for n, (message, words) in enumerate((
            ({"action": "undo"}, "nothing to undo"),
            ({"action": "stop"}, "no guided calibration is recording"),
            ({"action": "save", "path": "x.json"}, "no guided calibration fitted yet"),
            ({"action": "apply"}, "no guided calibration fitted yet"),
            ({"action": "explode"}, "action: one of start, stop, apply, undo, save"),
        )):  # fmt: skip
            ws.send(json.dumps({"type": "guided", "seq": n + 1, **message}))
            m = _said(ws, n + 1)
            assert m["type"] == "error" and m["for"] == "guided" and words in m["message"]
        ws.send(json.dumps({"type": "guided", "action": "start", "seq": 99}))
        while (m := _reply(ws)).get("phase") != "stopped":
            assert m["type"] != "state"  # nothing applied
        assert "shorter than the script" in m["why"], m
        m = _reply(ws)
        assert m["type"] == "error" and m["for"] == "guided" and "\n" not in m["message"]


def test_a_file_the_page_writes_over_is_said_replaced(server, tmp_path):
    """save (a preset, levels) and export: ``replaced`` where a file was there, which the
    page's note says ("replacing the file that was there"), never in silence."""
    there = tmp_path / "there.json"
    there.write_text("{}")
    with _open(server) as ws:
        for k, (kind, path) in enumerate([("preset", tmp_path / "new.json"), ("preset", there),
                                          ("levels", there)]):  # fmt: skip
            ws.send(json.dumps({"type": "save", "what": kind, "path": str(path), "seq": 40 + k}))
            _said(ws, 40 + k)  # the state
            saved = _said(ws, 40 + k)
            assert saved["type"] == "saved" and saved["replaced"] == (k > 0), saved
        for k, name in enumerate(("out.csv", "out.csv")):
            ws.send(json.dumps({"type": "export", "path": str(tmp_path / name), "seq": 50 + k}))
            done = _said(ws, 50 + k)
            assert done["type"] == "exported" and done["replaced"] == (k > 0), done


def test_levels_made_for_another_tracker_are_refused_on_load(server, tmp_path):
    """The page's load of levels checks the file's tracker as ``--calibration`` does: a
    MediaPipe calibration on this ARKit page is one line, the state kept (fifth red team:
    only the command line checked it)."""
    from faceclean.adjust import Adjust

    made = tmp_path / "mp.json"
    Adjust((), {"tracker": "mediapipe"}).save(made)
    with _open(server) as ws:
        ws.send(json.dumps({"type": "load", "what": "levels", "path": str(made), "seq": 61}))
        got = _said(ws, 61)
    assert got["type"] == "error" and got["for"] == "load", got
    assert "a calibration for tracker mediapipe, not arkit" in got["message"]
