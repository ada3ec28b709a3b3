"""Roles for the ``nice`` group tests: A measures its own thread's scheduling and tells B,
which writes it to the file ``$NICE_ROLES_OUT`` (the test reads it back)."""

from __future__ import annotations

import json
import os
import threading

from anodize import Endpoint

VARIABLE = "NICE_ROLES_OUT"
PROTOCOL = "global Told(A, B) = A -> B : seen(str). end"


def measurer(ep: Endpoint) -> None:
    tid = threading.get_native_id()
    seen = {"policy": os.sched_getscheduler(0), "nice": os.getpriority(os.PRIO_PROCESS, tid)}
    ep.send("B", "seen", json.dumps(seen))


def writer(ep: Endpoint) -> None:
    seen = ep.recv("A").payload
    with open(os.environ[VARIABLE], "w", encoding="utf-8") as out:
        out.write(seen)
