"""A single-producer/single-consumer byte ring in shared memory: a channel's stream of frames
between two group processes, with no system call per message while the receiver is awake.

The memory (a memfd the supervisor creates beside the channel's pipe, so both group processes
inherit it) holds a header and a data area whose size is a power of two::

    offset    0: tail      u64  bytes ever written; the sender's, published after the bytes
    offset   64: head      u64  bytes ever read; the receiver's, published after the copy
    offset  128: sleeping  u32  the receiver is about to block (ring the doorbell)
    offset  192: waiting   u32  the sender waits for room (ring the room eventfd)
    offset  256: closed    u32  the receiving end is gone (set by either side)
    offset 4096: data      ``capacity`` bytes

Each index lives on its own cache line. The indices only grow (64 bits do not wrap in practice);
a position is its index modulo the capacity. Both indices come from another process, so they
are hostile: every reader checks ``0 <= tail - head <= capacity`` before copying a byte
(:class:`RingCorruptError` otherwise), and copies only what was published.

The wake-ups are Dekker-style: the sender publishes ``tail`` then, after a full fence, reads
``sleeping``; the receiver sets ``sleeping`` then, after a full fence, reads ``tail`` again. One
of the two sees the other, so a receiver never sleeps on a published frame. The same holds for
``head`` and ``waiting``. Whoever sees the flag set clears it (compare-and-swap in C) and rings.

:func:`ring_write` and :func:`ring_read` are the compiled ones (``_frames.c``) when they were built
and ``ANODIZE_PURE_PYTHON`` is not set, else :func:`ring_write_python` and
:func:`ring_read_python`, the reference: tests/anodize/transport/test_ring.py compares them.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import threading
from collections.abc import Callable

from .._session import compiled

__all__ = ["HEADER_SIZE", "COMPILED", "RingCorruptError", "create_ring_memory", "ring_capacity", "ring_room",
           "ring_ready", "ring_read", "ring_read_python", "ring_write", "ring_write_python", "doorbell_due",
           "ring_closed", "ring_close", "set_flag", "take_flag", "take_flag_python", "SLEEPING", "WAITING",
           "CLOSED"]

HEADER_SIZE = 4096
TAIL, HEAD = 0, 64  # byte offsets of the two indices
SLEEPING, WAITING, CLOSED = 128, 192, 256  # byte offsets of the flags
DEFAULT_CAPACITY = 1 << 20  # as today's pipes: 1 MiB in flight at most


class RingCorruptError(ValueError):
    """The ring's published indices break its invariant: the peer wrote what it must not."""


# Python has no atomics. On x86-64 an aligned 8-byte (or 4-byte) load or store through a
# memoryview's cast is one mov: atomic, and (TSO) stores are seen in program order, loads are not
# reordered with loads. The one reordering TSO allows, a load passing an earlier store, is what
# the Dekker wake-up must forbid: a locked instruction is a full fence, and acquiring an
# uncontended lock executes one (a compare-and-swap), so _fence() is that.
_FENCE_LOCK = threading.Lock()


def _fence() -> None:
    _FENCE_LOCK.acquire()
    _FENCE_LOCK.release()


def _words(memory: memoryview) -> tuple[memoryview, memoryview]:
    header = memory[:HEADER_SIZE]
    return header.cast("Q"), header.cast("I")


def ring_capacity(memory: memoryview) -> int:
    """The data area's size (a power of two), from the mapping's length: never from the header."""
    return len(memory) - HEADER_SIZE


def _published(memory: memoryview) -> tuple[int, int, int]:
    """(tail, head, bytes published and unread), checked."""
    quads = memory[:HEADER_SIZE].cast("Q")
    head = quads[HEAD // 8]
    tail = quads[TAIL // 8]  # after head: what the sender published since is seen, never less
    used = (tail - head) % (1 << 64)
    if used > ring_capacity(memory):
        raise RingCorruptError(f"the ring's indices are impossible: {tail} written, {head} read, "
                          f"more than its {ring_capacity(memory)} bytes apart")
    return tail, head, used


def ring_ready(memory: memoryview) -> bool:
    """True when published bytes wait to be read (or the indices are broken: a read says so)."""
    quads = memory[:HEADER_SIZE].cast("Q")
    return quads[TAIL // 8] != quads[HEAD // 8]


def ring_write_python(memory: memoryview, data: bytes | bytearray | memoryview) -> int:
    """Copy as much of ``data`` as there is room for and publish it; the bytes written (0: full).

    Raises:
        RingCorruptError: the indices break the invariant (the receiver wrote them).
    """
    tail, _, used = _published(memory)
    capacity = ring_capacity(memory)
    size = min(len(data), capacity - used)
    if size <= 0:
        return 0
    at = HEADER_SIZE + tail % capacity
    first = min(size, HEADER_SIZE + capacity - at)
    source = memoryview(data).cast("B")
    memory[at:at + first] = source[:first]
    if first < size:  # wrapped around
        memory[HEADER_SIZE:HEADER_SIZE + size - first] = source[first:size]
    memory[:HEADER_SIZE].cast("Q")[TAIL // 8] = (tail + size) % (1 << 64)  # published after the bytes
    return size


def ring_read_python(memory: memoryview, into: bytearray, limit: int, room_fd: int) -> int:
    """Append up to ``limit`` published bytes to ``into``, publish the new head, and ring
    ``room_fd`` (an eventfd) when the sender waits for room. The bytes read.

    Raises:
        RingCorruptError: the indices break the invariant (the sender wrote them).
    """
    _, head, used = _published(memory)
    size = min(used, limit)
    if size <= 0:
        return 0
    capacity = ring_capacity(memory)
    at = HEADER_SIZE + head % capacity
    first = min(size, HEADER_SIZE + capacity - at)
    into += memory[at:at + first]
    if first < size:
        into += memory[HEADER_SIZE:HEADER_SIZE + size - first]
    memory[:HEADER_SIZE].cast("Q")[HEAD // 8] = (head + size) % (1 << 64)
    _fence()  # head published before the sender's flag is read (see the module's docstring)
    if take_flag_python(memory, WAITING):
        with contextlib.suppress(BlockingIOError):  # full (the sender holds it too and may fill it): woken anyway
            os.eventfd_write(room_fd, 1)
    return size


def ring_room(memory: memoryview) -> int:
    """The bytes the sender may write now.

    Raises:
        RingCorruptError: the indices break the invariant.
    """
    return ring_capacity(memory) - _published(memory)[2]


def doorbell_due(memory: memoryview) -> bool:
    """After publishing: True (and the flag cleared) when the receiver sleeps, so the caller rings."""
    _fence()  # the tail published before the receiver's flag is read
    return take_flag(memory, SLEEPING)


def set_flag(memory: memoryview, flag: int, value: int) -> None:
    """Store ``value`` in a flag, then fence: what the caller reads next comes after it."""
    memory[:HEADER_SIZE].cast("I")[flag // 4] = value
    _fence()


def take_flag_python(memory: memoryview, flag: int) -> bool:
    """Clear a set flag; True if it was set (the caller then rings). Not atomic in Python: two
    takers may both ring, which costs a spurious wake-up and loses none."""
    words = memory[:HEADER_SIZE].cast("I")
    if not words[flag // 4]:
        return False
    words[flag // 4] = 0
    return True


def ring_closed(memory: memoryview) -> bool:
    """The receiving end is gone (silenced, or its process noticed gone by the sender)."""
    return bool(memory[:HEADER_SIZE].cast("I")[CLOSED // 4])


def ring_close(memory: memoryview) -> None:
    """Mark the receiving end gone: the sender's next write fails (as EPIPE did on the pipe)."""
    set_flag(memory, CLOSED, 1)


def create_ring_memory(capacity: int = DEFAULT_CAPACITY) -> int:
    """A new memfd holding an empty ring of ``capacity`` bytes (a power of two); its descriptor."""
    if capacity <= 0 or capacity & (capacity - 1):
        raise ValueError(f"a ring's capacity must be a power of two, not {capacity}")
    fd = os.memfd_create("anodize-ring", os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
    try:
        os.ftruncate(fd, HEADER_SIZE + capacity)  # zero-filled: both indices 0, no flag set
        # Sealed: a peer that shrank it would kill the other side's reads with SIGBUS.
        fcntl.fcntl(fd, fcntl.F_ADD_SEALS, fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL)
    except OSError:
        os.close(fd)
        raise
    return fd


RingWrite = Callable[[memoryview, "bytes | bytearray | memoryview"], int]
RingRead = Callable[[memoryview, bytearray, int, int], int]
TakeFlag = Callable[[memoryview, int], bool]


def _compiled() -> tuple[RingWrite, RingRead, TakeFlag] | None:
    if not compiled.allowed():
        return None
    try:
        from ._frames import ring_read as read
        from ._frames import ring_take_flag as take
        from ._frames import ring_write as write
    except ImportError:  # built without a C compiler (or an older build): the reference works
        return None
    return write, read, take


_COMPILED = _compiled()
COMPILED: bool = _COMPILED is not None
ring_write: RingWrite = ring_write_python if _COMPILED is None else _COMPILED[0]
ring_read: RingRead = ring_read_python if _COMPILED is None else _COMPILED[1]
take_flag: TakeFlag = take_flag_python if _COMPILED is None else _COMPILED[2]
