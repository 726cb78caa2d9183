"""ui/priority.py on a real loopback connection: the process at the connection's far end,
in a session of its own, gets the autogroup nice asked; ours never does."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import pytest

from faceclean.ui import priority

pytestmark = pytest.mark.skipif(
    not Path("/proc/self/autogroup").exists(), reason="no autogroups on this system"
)

PEER = """
import socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
print(s.getsockname()[1], flush=True)
sys.stdin.read()  # hold the connection until told to go
"""


def test_the_page_end_of_a_connection_yields_and_we_do_not():
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    peer = subprocess.Popen([sys.executable, "-c", PEER, str(port)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, start_new_session=True)  # fmt: skip
    try:
        conn, _ = server.accept()
        page_port = int(peer.stdout.readline())
        ours = Path("/proc/self/autogroup").read_text()
        line = priority.lower_page(port, page_port, 5)
        assert "yield to the relay (autogroup nice 5" in line, line
        assert Path(f"/proc/{peer.pid}/autogroup").read_text().endswith("nice 5\n")
        assert Path("/proc/self/autogroup").read_text() == ours  # our own group: untouched
        assert priority.yield_cpu({peer.pid}, 6, priority._autogroup(peer.pid)) == []  # own kept
        # a port nobody holds: nothing found, nothing changed, said so
        assert "not found" in priority.lower_page(port, 1, 5)
        conn.close()
    finally:
        peer.stdin.close()
        peer.wait(10)
        server.close()
