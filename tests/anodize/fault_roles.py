"""Role functions that misbehave at the process level (module level: group processes import them)."""

from __future__ import annotations

import gc
import math
import os
import signal
import time
from multiprocessing.connection import Connection
from pathlib import Path

from anodize import Endpoint
from anodize._supervision import control


def server(ep: Endpoint) -> None:
    while (message := ep.recv("A")).label == "ping":
        ep.send("A", "pong", message.payload + 1)


def _note_pid(name: str) -> None:
    Path(os.environ["ANODIZE_TEST_DIR"], name).write_text(str(os.getpid()))


def forking_client(ep: Endpoint) -> None:
    """Leaves a child holding the channel's write end, and a shell's background job, then dies."""
    ep.send("B", "ping", 0)
    ep.recv("B")
    child = os.fork()
    if child == 0:  # keeps every descriptor of the group, pipes included
        time.sleep(60)
        os._exit(0)
    Path(os.environ["ANODIZE_TEST_DIR"], "child").write_text(str(child))
    os.system(f"sleep 60 & echo $! > {os.environ['ANODIZE_TEST_DIR']}/background")
    raise RuntimeError("the client failed, its children live on")


def freezing_client(ep: Endpoint) -> None:
    """Stops its whole process (as SIGSTOP from outside would) in the middle of the session."""
    ep.send("B", "ping", 0)
    ep.recv("B")
    os.kill(os.getpid(), signal.SIGSTOP)


def _control_connection() -> Connection:
    """The group's control connection (a duplex one: the channel pipes are one-way)."""
    return next(o for o in gc.get_objects()
                if isinstance(o, Connection) and o.readable and o.writable and not o.closed)


def half_a_control_message(ep: Endpoint) -> None:
    """Announces a large control message, sends three bytes of it, and nothing more."""
    os.write(_control_connection().fileno(), (100_000).to_bytes(4, "little") + b"abc")
    ep.sleep(math.inf)


def infinite_memory_report(ep: Endpoint) -> None:
    """A heartbeat claiming infinite memory (the supervisor once raised OverflowError on it)."""
    beat = control.Beat(at=time.monotonic(), memory=math.inf, peak=0)  # type: ignore[arg-type]
    os.write(_control_connection().fileno(), control.encode_control(beat))
    ep.sleep(math.inf)


def note_pid_and_freeze(ep: Endpoint) -> None:
    """Frozen, the group cannot even notice its supervisor is gone: only the kernel can end it."""
    _note_pid(f"frozen-{os.getpid()}")
    os.kill(os.getpid(), signal.SIGSTOP)


def stuck_in_c(ep: Endpoint) -> None:
    """Never reaches its endpoint again: a C call that does not return."""
    time.sleep(3600)


def hold_a_shared_mapping(ep: Endpoint) -> None:
    """Holds 160 MiB of anonymous *shared* memory: RLIMIT_DATA does not count it."""
    import mmap

    block = mmap.mmap(-1, 160 * 2**20, flags=mmap.MAP_SHARED)
    for offset in range(0, len(block), 4096):
        block[offset] = 1  # resident, page by page
    ep.sleep(math.inf)


def map_past_the_bound(ep: Endpoint) -> None:
    """Asks for a private mapping larger than the bound: the kernel refuses it (ENOMEM)."""
    import mmap

    mmap.mmap(-1, 512 * 2**20, flags=mmap.MAP_PRIVATE)
    ep.sleep(math.inf)
