"""A command told to stop (SIGTERM, SIGHUP, Ctrl-C) exits even if its unwinding or the
interpreter's teardown then hangs in native code: the kernel ends it EXIT_GRACE_S later."""

from __future__ import annotations

import signal
import subprocess
import sys


def test_a_hang_after_the_stop_is_ended_by_the_deadline():
    code = (
        "import time, faceclean.cli as c\n"
        "c.EXIT_GRACE_S = 1\n"
        "c._deadline()\n"
        "time.sleep(60)  # a teardown that never returns\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=30)
    assert p.returncode == -signal.SIGALRM


def test_the_deadline_leaves_a_handler_someone_installed_alone():
    code = (
        "import signal, time, faceclean.cli as c\n"
        "signal.signal(signal.SIGALRM, lambda *a: None)\n"
        "c.EXIT_GRACE_S = 1\n"
        "c._deadline()\n"
        "time.sleep(2)\n"
        "print('alive')\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    assert p.returncode == 0 and p.stdout.strip() == "alive"
