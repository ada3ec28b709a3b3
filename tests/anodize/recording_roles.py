"""Role functions for the recording tests that need group processes (importable by module path)."""

from __future__ import annotations

import os
import signal

from anodize import Endpoint

SENT_BEFORE_DYING = 50


def talker_killed_midway(ep: Endpoint) -> None:
    """Sends ``SENT_BEFORE_DYING`` numbers, waits for them to be written, then its process is killed."""
    for number in range(SENT_BEFORE_DYING):
        ep.send("Listener", "number", number)
    ep.sleep(0.5)  # the recorder flushes its part every 0.1 s
    os.kill(os.getpid(), signal.SIGKILL)


def listener(ep: Endpoint) -> None:
    while True:
        ep.recv("Talker")
