"""The tuning page's server: its own files over HTTP and one live channel (a WebSocket),
both on one loopback port, from the ``websockets`` library (the optional extra ``ui``).

Every request must carry the token printed at start: ``?token=...`` in the URL (the
page's first load, which sets it as a ``SameSite=Strict``, ``HttpOnly`` cookie named for
the port) or that cookie (the page's scripts and its live channel). Besides the token:
the ``Host`` header must name this server (a DNS-rebinding page's host does not), an
``Origin`` or ``Sec-Fetch-Site`` header must say the request comes from this page (no
other site can drive it: CSRF), and only the files in ``FILES`` are served (no path is
ever joined from the request: no traversal). Messages from the page are at most
``MAX_MESSAGE`` bytes of strict JSON objects; anything else closes the channel.
Replies are one-line FacecleanError texts where the CLI would refuse.
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import hmac
import http
import logging
import re
import secrets
import threading
from pathlib import Path
from typing import Any, Protocol
from urllib.parse import parse_qs, urlsplit

from faceclean import strict_json
from faceclean.errors import FacecleanError

HERE = Path(__file__).resolve().parent
STATIC = HERE / "static"
MAX_MESSAGE = 64 * 1024  # bytes of one message from the page
MAX_SENDS = 64  # messages queued to a slow page before the oldest views are dropped
TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8"}
TYPES[".css"] = "text/css; charset=utf-8"
MESH = "/mesh.json"  # the face the page draws (Session.mesh), besides the files
ONCE = ("Host", "Origin", "Sec-Fetch-Site")  # headers a request carries once at most


# the page's script modules in static/, each served at /NAME: ui.js (the page loads it)
# imports the others, one part of the page each
SCRIPTS = ("ui.js", "page.js", "channel.js", "controls.js", "sliders.js", "plots.js",
           "curves.js", "faces.js", "playback.js", "live.js", "status.js", "guided.js")  # fmt: skip


def files() -> dict[str, Path]:
    """URL path -> the file served there: the page, its scripts and style, the report's
    face view (report/face.js) and the pinned three.js the report uses."""
    from faceclean.report import build

    three = build.node_modules() / "three" / "build"
    return {
        "/": STATIC / "index.html",
        **{f"/{name}": STATIC / name for name in SCRIPTS},
        "/ui.css": STATIC / "ui.css",
        "/face.js": build.FACE_JS,
        "/three/three.module.js": three / "three.module.js",
        "/three/three.core.js": three / "three.core.js",
    }


class Client:
    """One open page: ``send(obj)`` JSON or ``send_bytes(data)``, from any thread."""

    def __init__(self, connection: Any) -> None:
        self.connection = connection
        self._lock = threading.Lock()

    def send(self, message: dict[str, Any]) -> None:
        """``message`` as strict JSON: a non-finite number goes out as null (missing)."""
        self._send(strict_json.dumps(message, separators=(",", ":")))

    def send_bytes(self, data: bytes) -> None:
        self._send(data)

    def _send(self, data: str | bytes) -> None:
        from websockets.exceptions import ConnectionClosed

        with self._lock, contextlib.suppress(ConnectionClosed, OSError):
            self.connection.send(data)


class Session(Protocol):
    """What the server serves: the offline take (ui/offline.py) or the relay (ui/live.py)."""

    def attach(self, client: Client) -> None: ...

    def detach(self, client: Client) -> None: ...

    def handle(self, client: Client, message: dict[str, Any]) -> None: ...

    def mesh(self) -> bytes: ...


class Server:
    """The page for ``session`` on ``host:port`` (0: a free port); ``start()`` serves in a
    thread, ``close()`` stops. ``url`` carries the token."""

    def __init__(self, session: Session, host: str = "127.0.0.1", port: int = 0) -> None:
        try:
            from websockets.sync.server import serve
        except ImportError:
            raise FacecleanError(
                "the tuning page needs the 'websockets' package: pip install 'faceclean[ui]'"
            ) from None
        self.session, self.host = session, host
        self.token = secrets.token_urlsafe(24)
        self.files = files()
        for path in self.files.values():
            if not path.is_file():
                raise FacecleanError(f"the tuning page's file {path.name} is missing ({path})")
        quiet = logging.getLogger("faceclean.ui.websockets")
        quiet.addHandler(logging.NullHandler())
        quiet.propagate = False
        try:
            self._server = serve(
                self._channel,
                host,
                port,
                process_request=self._request,
                max_size=MAX_MESSAGE,
                max_queue=16,
                compression=None,
                server_header=None,
                logger=quiet,
            )
        except OSError as e:
            raise FacecleanError(
                f"cannot serve the page on {host}:{port}: {e.strerror or e}"
            ) from None
        self.port = self._server.socket.getsockname()[1]
        names = {host, "127.0.0.1", "localhost"} | ({"[::1]"} if host in ("::1", "::") else set())
        names = {f"[{n}]" if ":" in n and not n.startswith("[") else n for n in names}
        self.hosts = {f"{n}:{self.port}" for n in names}
        self.origins = {f"http://{h}" for h in self.hosts}
        self.cookie = f"faceclean-ui-{self.port}"
        self._csp = _policy(self.files["/"].read_text(encoding="utf-8"))
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        shown = "127.0.0.1" if self.host in ("0.0.0.0", "") else self.host
        shown = f"[{shown}]" if ":" in shown else shown
        return f"http://{shown}:{self.port}/?token={self.token}"

    def start(self) -> Server:
        self._thread = threading.Thread(
            target=self._server.serve_forever, name="faceclean-ui", daemon=True
        )
        self._thread.start()
        return self

    def close(self) -> None:
        self._server.shutdown()
        if self._thread is not None:
            self._thread.join(5.0)

    def __enter__(self) -> Server:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- HTTP: every request, the live channel's handshake included ------------------------
    def refusal(self, headers: Any, target: str) -> str | None:
        """Why a request is refused (None: it is not): a header that must come once given
        twice, then Host, Origin, token, in that order."""
        for key in ONCE:  # two Hosts: which one would the browser have meant?
            if len(headers.get_all(key)) > 1:
                return f"the {key} header given more than once"
        if headers.get("Host") not in self.hosts:
            return "unknown Host (this server answers to 127.0.0.1 and localhost only)"
        origin = headers.get("Origin")
        if origin is not None and origin not in self.origins:
            return "a request from another site"
        if headers.get("Sec-Fetch-Site") not in (None, "same-origin", "none"):
            return "a request from another site"
        given = parse_qs(urlsplit(target).query).get("token", [""])[0]
        if not given:
            given = _cookie("; ".join(headers.get_all("Cookie")), self.cookie)
        if not hmac.compare_digest(given.encode(), self.token.encode()):
            return "no valid token (open the URL the command printed)"
        return None

    def _request(self, connection: Any, request: Any) -> Any:
        """The answer to one request (None: the live channel's handshake goes on). Never
        a 500: whatever goes wrong in here is a refusal of that request, in one line."""
        try:
            return self._answer(connection, request)
        except Exception as e:  # e.g. a header the library cannot parse as one value
            why = " ".join(f"{type(e).__name__}: {e}".split())[:200]
            return _text(connection, http.HTTPStatus.BAD_REQUEST, f"bad request ({why})")

    def _answer(self, connection: Any, request: Any) -> Any:
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        why = self.refusal(request.headers, request.path)
        if why is not None:
            return _text(connection, http.HTTPStatus.FORBIDDEN, why)
        path = urlsplit(request.path).path
        if path == "/live":
            return None  # the WebSocket handshake goes on (websockets checks the rest)
        target = self.files.get(path)
        if path == MESH:
            body, kind = self.session.mesh(), "application/json"
        elif target is None:
            return _text(connection, http.HTTPStatus.NOT_FOUND, "not a file of the tuning page")
        else:
            body, kind = target.read_bytes(), TYPES[target.suffix]
        headers = Headers()
        headers["Content-Type"] = kind
        headers["Content-Length"] = str(len(body))
        headers["Cache-Control"] = "no-store"
        headers["X-Content-Type-Options"] = "nosniff"
        headers["Referrer-Policy"] = "no-referrer"
        headers["Cross-Origin-Resource-Policy"] = "same-origin"
        if path == "/":
            headers["Content-Security-Policy"] = self._csp
            headers["X-Frame-Options"] = "DENY"
            headers["Set-Cookie"] = f"{self.cookie}={self.token}; Path=/; HttpOnly; SameSite=Strict"
        return Response(200, "OK", headers, body)

    # -- the live channel -------------------------------------------------------------------
    def _channel(self, connection: Any) -> None:
        from websockets.exceptions import ConnectionClosed

        client = Client(connection)
        self.session.attach(client)
        try:
            for raw in connection:
                if isinstance(raw, bytes):
                    connection.close(1003, "text messages only")
                    return
                receive(self.session, client, raw)
        except ConnectionClosed:
            pass
        finally:
            self.session.detach(client)


def receive(session: Session, client: Client, raw: str) -> None:
    """Parse one text message from the page and let ``session`` answer it. Never raises:
    bad JSON, a non-object or a refusal is answered by one ``error`` message (``for``: the
    type it answers), anything else too, as an internal error (a bug: ``faceclean fuzz``
    looks for one)."""
    try:
        message = strict_json.loads(raw.encode("utf-8"), "message")
    except FacecleanError as e:
        client.send({"type": "error", "message": f"faceclean: {e}"})
        return
    if not isinstance(message, dict) or not isinstance(message.get("type"), str):
        client.send({"type": "error", "message": "faceclean: a message is an object"})
        return
    try:
        session.handle(client, message)
    except FacecleanError as e:
        reply = {"type": "error", "message": f"faceclean: {e}"}
        client.send({**reply, "for": message["type"], "seq": _seq(message)})
    except Exception as e:  # never a dead channel: one line, as cli.main says it
        why = f"faceclean: internal error: {type(e).__name__}: {e}"
        client.send({"type": "error", "message": why, "for": message["type"]})


def _seq(message: dict[str, Any]) -> int | None:
    seq = message.get("seq")
    return seq if isinstance(seq, int) and not isinstance(seq, bool) else None


def _text(connection: Any, status: http.HTTPStatus, why: str) -> Any:
    return connection.respond(status, f"faceclean ui: {why}\n")


def _cookie(header: str, name: str) -> str:
    for part in header.split(";"):
        key, _, value = part.strip().partition("=")
        if key == name:
            return value
    return ""


def _policy(index: str) -> str:
    """The page's Content-Security-Policy: its own files only, the inline import map by
    its hash, the live channel on the same host."""
    found = re.search(r'<script type="importmap">(.*?)</script>', index, re.S)
    digest = hashlib.sha256((found[1] if found else "").encode()).digest()
    importmap = "'sha256-" + base64.b64encode(digest).decode() + "'"
    return (
        f"default-src 'none'; script-src 'self' {importmap}; style-src 'self'; "
        "img-src 'self' data:; connect-src 'self'; base-uri 'none'; form-action 'none'; "
        "frame-ancestors 'none'"
    )
