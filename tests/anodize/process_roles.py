"""Role functions for the process-transport tests (module level: group processes import them)."""

from __future__ import annotations

import os
import signal
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from anodize import Endpoint

MESSAGES = 1_000_000
FRAMES = 10_000


@dataclass(frozen=True)
class Frame:
    """A numbered image and the CRC-32 of its bytes, as the sender computed it."""

    index: int
    crc: int
    pixels: np.ndarray


class Opaque:
    """A plain class named by a protocol: travels pickled, through the restricted unpickler."""

    def __init__(self, value: int) -> None:
        self.value = value


class Unnamed:
    """A class no protocol names: refused at the sender."""


# ---- streams: nothing lost, duplicated or reordered -----------------------------------------
def count_source(ep: Endpoint) -> None:
    for i in range(MESSAGES):
        ep.send("B", "item", i)
    ep.send("B", "fin")


def count_sink(ep: Endpoint) -> None:
    expected = 0
    while (message := ep.recv("A")).label == "item":
        if message.payload != expected:
            raise AssertionError(f"message {expected} expected, got {message.payload}")
        expected += 1
    if expected != MESSAGES:
        raise AssertionError(f"{expected} messages arrived, {MESSAGES} were sent")


def frame_pixels(index: int) -> np.ndarray:
    """Frame ``index``: a few sizes (so the ring must grow), content that depends on the index."""
    height = (160, 200, 120)[index % 3]
    rng = np.random.default_rng(index)
    return rng.integers(0, 256, size=(height, 160, 3), dtype=np.uint8)


def frame_source(ep: Endpoint) -> None:
    for i in range(FRAMES):
        pixels = frame_pixels(i % 64)
        if i % 2:  # every other frame is filled in place in its shared-memory slot: no copy
            slot = ep.buffer("B", pixels.shape, pixels.dtype)
            slot[:] = pixels
            pixels = slot
        ep.send("B", "frame", Frame(i, zlib.crc32(pixels), pixels))
    ep.send("B", "fin")


def frame_sink(ep: Endpoint) -> None:
    kept = []  # holding some frames keeps their slots busy: the sender must wait for others
    expected = 0
    while (message := ep.recv("A")).label == "frame":
        frame = message.payload
        if frame.index != expected or zlib.crc32(frame.pixels) != frame.crc:
            raise AssertionError(f"frame {expected}: got index {frame.index}, crc mismatch "
                                 f"{zlib.crc32(frame.pixels) != frame.crc}")
        if not np.array_equal(frame.pixels, frame_pixels(expected % 64)):
            raise AssertionError(f"frame {expected}: pixels differ")
        kept = [*kept, frame.pixels][-3:]
        expected += 1
    if expected != FRAMES:
        raise AssertionError(f"{expected} frames arrived, {FRAMES} were sent")


# ---- ping-pong ------------------------------------------------------------------------------
def client(ep: Endpoint) -> None:
    for i in range(50):
        ep.send("B", "ping", i)
        if ep.recv("B").payload != i + 1:
            raise AssertionError("wrong pong")
    ep.send("B", "stop")


def server(ep: Endpoint) -> None:
    while (message := ep.recv("A")).label == "ping":
        ep.send("A", "pong", message.payload + 1)


def injecting_client(ep: Endpoint) -> None:
    """Bypasses its own monitor and writes a message the protocol forbids into the channel."""
    channel, _ = ep._out["B"]
    channel.put(("pong", 7))  # A never sends pong


def garbling_client(ep: Endpoint) -> None:
    """Writes bytes that are no frame at all into the channel."""
    channel, _ = ep._out["B"]
    channel._write(b"\x05\x00\x00\x00Zjunk")  # into the channel's stream (its ring), as a frame would go


def crashing_client(ep: Endpoint) -> None:
    """Sends once, then its whole process dies (as a segfault or the OOM killer would do it)."""
    ep.send("B", "ping", 0)
    os.kill(os.getpid(), signal.SIGKILL)


def patient_server(ep: Endpoint) -> None:
    """Answers the first ping, then waits for the next one (which never comes)."""
    message = ep.recv("A")
    ep.send("A", "pong", message.payload + 1)
    ep.recv("A")


def once_failing_client(ep: Endpoint) -> None:
    """Fails in its first incarnation (marked by a file), conforms in the next ones."""
    marker = Path(os.environ["ANODIZE_TEST_MARKER"])
    if not marker.exists():
        marker.write_text("failed once")
        raise RuntimeError("first incarnation fails")
    client(ep)


def sleepy_server(ep: Endpoint) -> None:
    """Never reaches a send or receive: only killing its process ends it."""
    time.sleep(3600)


# ---- memory ---------------------------------------------------------------------------------
def hog(ep: Endpoint) -> None:
    """Allocates 8 MiB at a time, touching every page, telling its peer how far it got."""
    hoard = []
    for i in range(10_000):
        hoard.append(np.ones(8 * 2**20, dtype=np.uint8))
        ep.send("K", "chunk", i)
    ep.send("K", "fin")


def hog_sink(ep: Endpoint) -> None:
    while ep.recv("H").label == "chunk":
        pass


def steady_controller(ep: Endpoint) -> None:
    """A 100 Hz loop for 1.5 s (it sleeps: safe at a raised priority)."""
    period, start = 0.01, time.monotonic()
    for i in range(150):
        ep.send("S", "tick", i)
        time.sleep(max(0.0, start + (i + 1) * period - time.monotonic()))
    ep.send("S", "done")


def steady_sensor(ep: Endpoint) -> None:
    expected = 0
    while (message := ep.recv("C")).label == "tick":
        if message.payload != expected:
            raise AssertionError("tick out of order")
        expected += 1


# ---- payloads -------------------------------------------------------------------------------
def opaque_sender(ep: Endpoint) -> None:
    ep.send("B", "thing", Opaque(41))
    ep.send("B", "nested", {"key": [1, 2.5, "x", b"y", None, (True, frozenset({3}))]})


def opaque_receiver(ep: Endpoint) -> None:
    thing = ep.recv("A").payload
    if not isinstance(thing, Opaque) or thing.value != 41:
        raise AssertionError(f"got {thing!r}")
    nested = ep.recv("A").payload
    if nested != {"key": [1, 2.5, "x", b"y", None, (True, frozenset({3}))]}:
        raise AssertionError(f"got {nested!r}")


def unnamed_sender(ep: Endpoint) -> None:
    ep.send("B", "thing", Opaque(1))
    ep.send("B", "nested", {"key": Unnamed()})


def waiting_receiver(ep: Endpoint) -> None:
    ep.recv("A")
    ep.recv("A")


# ---- scheduling -----------------------------------------------------------------------------
def where_sender(ep: Endpoint) -> None:
    """Tells its peer which CPUs and which policy its thread runs with."""
    policy = {os.SCHED_FIFO: "fifo", os.SCHED_OTHER: "other"}.get(os.sched_getscheduler(0), "?")
    ep.send("B", "where", f"{sorted(os.sched_getaffinity(0))} {policy} {os.getpriority(os.PRIO_PROCESS, 0)}")


def where_receiver(ep: Endpoint) -> None:
    expected = os.environ["ANODIZE_TEST_EXPECT"]
    got = ep.recv("A").payload
    if got != expected:
        raise AssertionError(f"role A runs with {got}, expected {expected}")


# ---- review regressions: blocked senders, stops, oversized frames ---------------------------
def flooding_sender(ep: Endpoint) -> None:
    """Sends until the pipe is full and it blocks (its receiver never reads)."""
    blob = b"x" * 60_000
    while True:
        ep.send("B", "blob", blob)


def failing_non_reader(ep: Endpoint) -> None:
    time.sleep(1.0)
    raise RuntimeError("B gives up without reading")


def sleeping_non_reader(ep: Endpoint) -> None:
    time.sleep(3600)


def hello_sender(ep: Endpoint) -> None:
    ep.send("D", "hello")
    ep.recv("D")


def lingering_receiver(ep: Endpoint) -> None:
    """Keeps its group's process alive long after its group mate B failed."""
    ep.recv("C")
    time.sleep(3600)


def stoppable_non_reader(ep: Endpoint) -> None:
    """Waits in a receive (so a stop reaches it) without ever taking the flood."""
    ep.recv("D")


def huge_frame_client(ep: Endpoint) -> None:
    """Announces a 2 GiB frame: the receiver must not try to buffer it."""
    channel, _ = ep._out["B"]
    channel._write((2**31).to_bytes(4, "little") + b"M" * 1000)  # into the channel's ring


def any_receiver(ep: Endpoint) -> None:
    ep.recv_any()


def hog_in_a_thread(ep: Endpoint) -> None:
    """Sends one chunk, then leaks from a helper thread it started (not the role's own)."""
    import threading

    def leak() -> None:
        hoard = []
        while True:
            hoard.append(np.ones(8 * 2**20, dtype=np.uint8))

    ep.send("K", "chunk", 0)
    threading.Thread(target=leak, daemon=True).start()
    ep.sleep(60.0)
    ep.send("K", "fin")


def sleeper(ep: Endpoint) -> None:
    """Paces itself with ep.sleep for far longer than any test's timeout."""
    while True:
        ep.sleep(60.0)
        ep.send("B", "item", 1)


@dataclass(frozen=True, slots=True)
class Inner:
    """Not named by any sort: it crosses only as a field of one that is."""

    values: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class Outer:
    label: str
    inner: Inner
    more: tuple[Inner, ...] = ()


def send_nested(ep: Endpoint) -> None:
    ep.send("B", "outer", Outer("a", Inner((1.0, 2.5)), (Inner(()), Inner((3.0,)))))


def receive_nested(ep: Endpoint) -> None:
    received = ep.recv("A").payload
    assert received == Outer("a", Inner((1.0, 2.5)), (Inner(()), Inner((3.0,)))), received


def sleep_for_ever(ep: Endpoint) -> None:
    import math

    ep.send("B", "item", 0)
    ep.sleep(math.inf)
