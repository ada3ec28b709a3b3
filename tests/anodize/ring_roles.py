"""Role functions for the shared-memory ring tests (module level: group processes import them)."""

from __future__ import annotations

import contextlib
import errno
import gc
import glob
import mmap
import os
import resource
import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from anodize import Endpoint, PeerFailedError

SHAPE = (240, 320, 3)  # 225 KiB: over the inline limit, so each frame takes a ring slot
KEPT = 20  # frames a hoarding receiver keeps: more than the ring's 8 slots
WINDOW_FRAMES = 200
BLOBS = 1500  # 100 KiB each: 150 MiB through a group bounded at 64 MiB
BLOB = 100 * 1024


@dataclass(frozen=True)
class Frame:
    """A numbered image and the CRC-32 of its bytes, as the sender computed it."""

    index: int
    crc: int
    pixels: np.ndarray


def pixels(index: int) -> np.ndarray:
    """Frame ``index``'s content: different for every index."""
    return np.random.default_rng(index).integers(0, 256, size=SHAPE, dtype=np.uint8)


def _frame(ep: Endpoint, index: int) -> Frame:
    """Even frames are filled in a slot from ``ep.buffer()``, odd ones are copied in by the send."""
    image = pixels(index)
    if index % 2 == 0:
        slot = ep.buffer("B", SHAPE, np.uint8)
        slot[:] = image
        image = slot
    return Frame(index, zlib.crc32(image), image)


def _check(frame: Frame, index: int) -> None:
    if frame.index != index or zlib.crc32(frame.pixels) != frame.crc or \
            not np.array_equal(frame.pixels, pixels(index)):
        raise AssertionError(f"frame {index} arrived as frame {frame.index}, or its pixels differ")


# ---- a receiver that holds its slots --------------------------------------------------------
def hoard_source(ep: Endpoint) -> None:
    for i in range(KEPT):
        ep.send("B", "frame", _frame(ep, i))
    ep.send("B", "fin")


def window_source(ep: Endpoint) -> None:
    for i in range(WINDOW_FRAMES):
        ep.send("B", "frame", _frame(ep, i))
    ep.send("B", "fin")


def hoarding_sink(ep: Endpoint) -> None:
    """Keeps every frame alive until the end, then checks none of them changed."""
    kept: list[Frame] = []
    while (message := ep.recv("A")).label == "frame":
        _check(message.payload, len(kept))
        kept.append(message.payload)
    if len(kept) != KEPT:
        raise AssertionError(f"{len(kept)} frames arrived, {KEPT} were sent")
    for index, frame in enumerate(kept):
        _check(frame, index)


def window_sink(ep: Endpoint) -> None:
    """Keeps the last 8 frames alive (a frame-history window): as many as the ring has slots."""
    window: list[Frame] = []
    count = 0
    while (message := ep.recv("A")).label == "frame":
        _check(message.payload, count)
        window = [*window, message.payload][-8:]
        for frame in window:
            _check(frame, frame.index)
        count += 1
    if count != WINDOW_FRAMES:
        raise AssertionError(f"{count} frames arrived, {WINDOW_FRAMES} were sent")


def cycle_sink(ep: Endpoint) -> None:
    """Lets every frame fall into a reference cycle, with the cyclic collector off."""
    gc.disable()
    try:
        count = 0
        while (message := ep.recv("A")).label == "frame":
            _check(message.payload, count)
            cycle: list[object] = [message.payload]
            cycle.append(cycle)  # unreachable after this iteration, freed only by gc
            count += 1
        if count != KEPT:
            raise AssertionError(f"{count} frames arrived, {KEPT} were sent")
    finally:
        gc.enable()


# ---- a sender that truncates its ring -------------------------------------------------------
def truncating_source(ep: Endpoint) -> None:
    """Sends a frame, then tries to shrink the memory behind it under the receiver's mapping."""
    ep.send("B", "frame", _frame(ep, 0))
    outcomes = set()
    for name in os.listdir("/proc/self/fd"):
        with contextlib.suppress(OSError):
            if os.readlink(f"/proc/self/fd/{name}").startswith("/memfd:anodize-"):
                outcomes.add(_truncate(lambda fd=int(name): os.ftruncate(fd, 0)))
                reopened = os.open(f"/proc/self/fd/{name}", os.O_RDWR)
                outcomes.add(_truncate(lambda fd=reopened: os.ftruncate(fd, 0)))
                os.close(reopened)
    # Rings as files in /dev/shm (named after the supervisor, our parent, and the channel).
    for path in glob.glob(f"/dev/shm/anodize-{os.getppid()}-*-{b'A'.hex()}-{b'B'.hex()}-*"):
        outcomes.add(_truncate(lambda path=path: os.truncate(path, 0)))
    ep.send("B", "truncated", ",".join(sorted(outcomes)) or "no ring found")


def _truncate(attempt: Callable[[], object]) -> str:
    try:
        attempt()
    except OSError as error:
        return errno.errorcode.get(error.errno or 0, str(error.errno))
    return "truncated"


def unharmed_sink(ep: Endpoint) -> None:
    """Reads every byte of the frame after its sender tried to shrink the ring under it."""
    frame = ep.recv("A").payload
    outcome = ep.recv("A").payload
    _check(frame, 0)  # a truncated mapping would raise SIGBUS here
    if outcome != "EPERM":
        raise AssertionError(f"the sender's truncations ended: {outcome}")


# ---- write after send -----------------------------------------------------------------------
def rewriting_source(ep: Endpoint) -> None:
    """Sends a frame filled in its slot, then tries to change it three ways."""
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # the fault below must not leave a core file
    frame = _frame(ep, 0)
    earlier_view = frame.pixels.reshape(-1)  # made before the send: numpy still calls it writable
    ep.send("B", "frame", frame)
    outcomes = []
    try:
        frame.pixels[0, 0, 0] = 1
        outcomes.append("write allowed")
    except ValueError:
        outcomes.append("write refused")
    try:
        frame.pixels.flags.writeable = True
        outcomes.append("flip allowed")
    except ValueError:
        outcomes.append("flip refused")
    ep.send("B", "checked", "; ".join(outcomes))
    earlier_view[:] = 0  # the pages are read-only now: this faults, here, in the sender
    ep.send("B", "after", 0)


def watching_sink(ep: Endpoint) -> None:
    """Receives the frame and keeps checking it after the sender tried to rewrite it."""
    frame = ep.recv("A").payload
    _check(frame, 0)
    checked = ep.recv("A").payload
    if checked != "write refused; flip refused":
        raise AssertionError(f"the sender could change a sent frame: {checked}")
    with contextlib.suppress(PeerFailedError):  # the sender dies of its own write
        ep.recv("A")
    _check(frame, 0)


def inspecting_sink(ep: Endpoint) -> None:
    """Looks for a way from a received array to the ring's memory."""
    frame = ep.recv("A").payload
    _check(frame, 0)
    found = reachable_buffers(frame.pixels)
    if found:
        raise AssertionError(f"a received array leads to {found}")
    if frame.pixels.flags.writeable:
        raise AssertionError("a received array is writable")
    try:
        frame.pixels.flags.writeable = True
    except ValueError:
        pass
    else:
        raise AssertionError("a received array can be made writable")


def one_frame_source(ep: Endpoint) -> None:
    ep.send("B", "frame", _frame(ep, 0))


def reachable_buffers(array: object) -> list[str]:
    """The mmaps and memoryviews reachable from ``array`` through ``base``, attributes and slots."""
    found = []
    seen = set()
    pending = [array]
    while pending:
        item = pending.pop()
        if id(item) in seen or isinstance(item, (int, float, str, bytes, type(None))):
            continue
        seen.add(id(item))
        if isinstance(item, (mmap.mmap, memoryview)):
            found.append(type(item).__name__)
            continue
        if isinstance(item, dict):
            pending.extend(item.values())
            continue
        if isinstance(item, (list, tuple)):
            pending.extend(item)
            continue
        pending.append(getattr(item, "base", None))
        pending.extend(getattr(item, "__dict__", {}).values())
        for cls in type(item).__mro__:
            pending.extend(getattr(item, slot, None) for slot in getattr(cls, "__slots__", ()))
    return found


# ---- a sender that ends at once -------------------------------------------------------------
def late_sink(ep: Endpoint) -> None:
    """Reads only after its sender's process has (very likely) ended."""
    ep.sleep(1.0)
    _check(ep.recv("A").payload, 0)


# ---- back pressure into a parallel-branch receiver ------------------------------------------
def blob_source(ep: Endpoint) -> None:
    for i in range(BLOBS):
        ep.send("B", "blob", i.to_bytes(8, "little") + bytes(BLOB - 8))
    ep.send("B", "fin")


def hello_sender(ep: Endpoint) -> None:
    ep.send("B", "hello")


def slow_parallel_sink(ep: Endpoint) -> None:
    """A role with parallel branches (its channels are bridged) that reads the stream slowly."""
    ep.recv("C")
    count = 0
    while (message := ep.recv("A")).label == "blob":
        if int.from_bytes(message.payload[:8], "little") != count or len(message.payload) != BLOB:
            raise AssertionError(f"blob {count} arrived out of order or cut")
        count += 1
        ep.sleep(0.001)
    if count != BLOBS:
        raise AssertionError(f"{count} blobs arrived, {BLOBS} were sent")
