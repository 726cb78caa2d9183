"""Relay endpoints as URLs: ``vmc://HOST:PORT``, ``livelink://HOST:PORT``,
``ifacialmocap://HOST:PORT`` (input only).

The host defaults to 127.0.0.1 (listening on every interface needs an explicit
``0.0.0.0``); the port defaults to the protocol's usual one. ``vmc://`` output takes
``?names=keep|arkit|pascal|lr`` (the spelling of the names it sends; keep = as received).
"""

from __future__ import annotations

import socket
from dataclasses import dataclass, field
from urllib.parse import parse_qs, urlsplit

from faceclean.errors import FacecleanError
from faceclean.relay import ifacialmocap, livelink, vmc
from faceclean.relay.frame import Decoder, Encoder

PORTS = {"vmc": vmc.DEFAULT_PORT, "livelink": livelink.DEFAULT_PORT}
PORTS["ifacialmocap"] = ifacialmocap.DEFAULT_PORT
INPUTS = ("vmc", "livelink", "ifacialmocap")
OUTPUTS = ("vmc", "livelink")


@dataclass(frozen=True)
class Endpoint:
    """A parsed relay URL."""

    scheme: str
    host: str
    port: int
    options: dict[str, str] = field(default_factory=dict)

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.scheme}://{host}:{self.port}"

    def sockaddr(self) -> tuple[int, tuple]:
        """(address family, socket address) for this host and port (UDP)."""
        try:
            info = socket.getaddrinfo(self.host, self.port, type=socket.SOCK_DGRAM)
        except (socket.gaierror, UnicodeError) as e:
            raise FacecleanError(f"{self}: cannot resolve host {self.host!r} ({e})") from None
        family, _, _, _, addr = info[0]
        return family, addr

    def decoder(self) -> Decoder:
        return {"vmc": vmc.Decoder, "livelink": livelink.Decoder}.get(
            self.scheme, ifacialmocap.Decoder
        )()

    def encoder(self) -> Encoder:
        if self.scheme == "vmc":
            return vmc.Encoder(names=self.options.get("names", "keep"))
        return livelink.Encoder()


def parse(url: str, role: str = "listen") -> Endpoint:
    """A relay URL -> Endpoint; ``role`` is "listen" or "send" (which schemes it allows)."""
    allowed = INPUTS if role == "listen" else OUTPUTS
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as e:
        raise FacecleanError(f"bad URL {url!r} ({e})") from None
    scheme = parts.scheme.lower()
    if scheme not in allowed:
        raise FacecleanError(
            f"bad {role} URL {url!r}: use " + " or ".join(f"{s}://HOST:PORT" for s in allowed)
        )
    if parts.path not in ("", "/") or parts.username or parts.fragment:
        raise FacecleanError(f"bad URL {url!r}: only {scheme}://HOST:PORT[?options]")
    if port is None:
        port = PORTS[scheme]
    if port == 0 and role == "send":
        raise FacecleanError(f"bad send URL {url!r}: port 0")
    options = {k: v[-1] for k, v in parse_qs(parts.query, keep_blank_values=True).items()}
    unknown = set(options) - ({"names"} if scheme == "vmc" and role == "send" else set())
    if unknown == {"names"}:  # a send option given to a listen or a Live Link URL
        raise FacecleanError(
            f"bad URL {url!r}: ?names= is for a vmc:// --send URL (the names it sends)"
        )
    if unknown:
        raise FacecleanError(f"bad URL {url!r}: unknown option {sorted(unknown)[0]!r}")
    if options.get("names", "keep") not in vmc.NAME_STYLES:
        raise FacecleanError(f"bad URL {url!r}: names= one of {', '.join(vmc.NAME_STYLES)}")
    return Endpoint(scheme, parts.hostname or "127.0.0.1", port, options)
