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
    gc.unfreeze()  # the group froze what its start made (the connection too): the collector lists it again
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


def fork_then_sigkilled(ep: Endpoint) -> None:
    """Leaves a forked child and a shell's background job holding every descriptor the group
    inherited, then its process is SIGKILLed (nothing of the group runs after that)."""
    ep.send("B", "ping", 0)
    ep.recv("B")
    child = os.fork()
    if child == 0:
        time.sleep(90)
        os._exit(0)
    Path(os.environ["ANODIZE_TEST_DIR"], "child").write_text(str(child))
    os.system(f"sleep 90 & echo $! > {os.environ['ANODIZE_TEST_DIR']}/background")
    time.sleep(0.3)  # its children are seen by the supervisor (it reads the tree ten times a second)
    os.kill(os.getpid(), signal.SIGKILL)


def fill_a_tmpfs_file(ep: Endpoint) -> None:
    """Writes 256 MiB, 1 MiB at a time, to a file on tmpfs (/dev/shm) and keeps it open: pages
    of the file system, not of the process (RLIMIT_DATA and VmRSS do not see them)."""
    with open(f"/dev/shm/anodize-test-{os.getpid()}", "wb") as file:
        os.unlink(file.name)  # open, unnamed: the kernel frees it with the process
        chunk = b"x" * 2**20
        for _ in range(256):
            file.write(chunk)
            file.flush()
        ep.sleep(math.inf)


def grow_past_the_bound(ep: Endpoint) -> None:
    """Allocates 1 MiB blocks, touching each page, until the bound refuses one (MemoryError)."""
    blocks = []
    while True:
        block = bytearray(2**20)
        for offset in range(0, len(block), 4096):
            block[offset] = 1
        blocks.append(block)


def hold_the_gil_for_good(ep: Endpoint) -> None:
    """A backtracking regular expression of 2**40 steps: it holds the GIL for longer than any
    test lasts (issue 27's example)."""
    import re

    re.match("(a+)+b", "a" * 40)


def hold_the_gil_in_stretches(ep: Endpoint) -> None:
    """Never reaches its endpoint again: a C call that holds the GIL (as a C extension's or a
    backtracking regular expression's would) for twice the runner's HELD_UP of wall
    time, again and again, so each stretch counts whatever the machine's speed: libc's
    ``poll`` with no descriptors, called through ``ctypes.PyDLL`` (which keeps the GIL, unlike
    ``CDLL``). A fixed amount of work (a backtracking regular expression's) took half a second
    on one machine and less on a faster one, where no stretch counted."""
    import ctypes

    from anodize._supervision import threads

    libc = ctypes.PyDLL(None)
    while True:
        libc.poll(None, 0, round(2 * threads.HELD_UP * 1000))
        # The GIL free for a moment between two stretches: the supervisor makes a whole step
        # in it, instead of losing a stretch at each of its own calls that lets the GIL go.
        time.sleep(0.05)
