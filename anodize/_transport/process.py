"""The process transport's links: a shared-memory byte ring and an OS pipe per channel.

A group's :class:`~anodize._transport.network.GroupNetwork` links its channels to
roles of other groups with :class:`PipeLinks`. A channel's frames
(:mod:`anodize._transport.codec`) travel through a single-producer/single-consumer byte
ring in memory both processes map (:mod:`anodize._transport.ring`): a send is a copy and
a store, with no system call while the receiver is awake. The channel's pipe stays for
what only the kernel can give: a receiver that has nothing to read sleeps in ``poll()`` on
it and the sender writes one doorbell byte there; and only the sending group holds its
write end, so when that group's process dies the receiver reads end-of-file: a crashed
peer is always noticed, never waited on. A role that fails in a live process has a
failure frame written after its last message, so nothing it sent is lost. Large arrays
go through shared-memory slots (:mod:`anodize._transport.shm`). Built without a ring
(``PipeLinks(fds)``), a channel's frames travel in the pipe itself, as before the ring.
"""

from __future__ import annotations

import contextlib
import errno
import mmap
import os
import select
import threading
import time
from collections import deque
from collections.abc import Callable, Collection, Iterable, Mapping
from contextlib import AbstractContextManager
from multiprocessing import reduction
from multiprocessing.connection import Connection
from operator import itemgetter
from queue import Empty
from typing import Any, NamedTuple, Protocol

from .._session.channel import STOP, Corrupt, PeerFailure
from ..errors import AnodizeError, PeerFailedError, RoleStopped
from .codec import HEADER, MAX_FRAME, Codec, DecodeError, EncodeError, FrameKind
from .frames import SmallFrameWriter
from .links import LinkNetwork, PayloadError, WritingEnd
from .ring import (
    SLEEPING,
    WAITING,
    create_ring_memory,
    doorbell_due,
    ring_close,
    ring_closed,
    ring_read,
    ring_ready,
    ring_room,
    ring_write,
    set_flag,
    take_flag,
)
from .spin import SpinPolicy

__all__ = ["PipeLinks", "PipeSender", "PipeReceiver", "Ring", "LinkEnd", "SharedFd", "channel_ends", "map_ring",
           "Spin"]

# Reads of at most 64 KiB: larger ones make malloc mmap and munmap a buffer on every call.
_READ_SIZE = 64 * 1024
_MESSAGE = itemgetter(0)  # of a decoded (message, frame size) entry
# A ring's receiver takes at most this much at once. The decoder turns all it took into message
# objects at once: 64 KiB of small frames are some 4,000 of them (over half a MiB of objects),
# evicted from the cache before a batch of 1,024 reaches them, which cost recv_many a third more
# CPU per message than 16 KiB (about one such batch). No system call is saved by more: the ring
# is read without one.
_RING_READ = 16 * 1024
_PIPE_SIZE = 1 << 20  # ask the kernel for 1 MiB pipes: fewer blocked senders when streaming
# A failure frame stays within PIPE_BUF (4096 bytes; 4 UTF-8 bytes a character at most): one
# write, which a reader sees whole even when the writer dies right after it.
_CAUSE_CHARS = (select.PIPE_BUF - 16) // 4


_ROOM_CHECK = 1.0  # seconds between a waiting sender's looks at the supervisor's word on its receiver


class Ring(NamedTuple):
    """A channel's ring, as one process sees it: the mapped memory and the sender's room eventfd."""

    memory: memoryview
    room_fd: int


class Spin(Protocol):
    """How a receiver may wait a little, awake, before it sleeps (set by another part of anodize)."""

    def wait(self, ready: Callable[[], bool], limit: float | None = None) -> bool:
        """Return True as soon as ``ready()`` is, False when it is time to sleep (or ``limit``
        seconds, the receive's own timeout, have passed)."""


class SharedFd:
    """A file descriptor that a spawned group process receives (duplicated into it as a pipe's
    :class:`~multiprocessing.connection.Connection` is)."""

    def __init__(self, fd: int) -> None:
        self.fd = fd

    def __reduce__(self) -> tuple[Callable[[Any], SharedFd], tuple[object]]:
        return _rebuild_fd, (reduction.DupFd(self.fd),)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.close(self.fd)


def _rebuild_fd(duplicate: Any) -> SharedFd:
    return SharedFd(duplicate.detach())


class LinkEnd:
    """One group's end of a channel to another group: the pipe's end, the ring's memory (a memfd)
    and the sender's room eventfd. Sent to the group's process with its spec."""

    def __init__(self, pipe: Connection, memory: SharedFd, room: SharedFd) -> None:
        self.pipe = pipe
        self.memory = memory
        self.room = room

    def fileno(self) -> int:
        """The pipe's end."""
        return self.pipe.fileno()

    def close(self) -> None:
        """Close what this process holds of it (the supervisor, once the groups have theirs)."""
        self.pipe.close()
        self.memory.close()
        self.room.close()

    def ring(self) -> Ring:
        """Map the ring (in the group's process); the memfd is closed, the mapping stays."""
        memory = map_ring(self.memory.fd)
        self.memory.close()
        os.set_inheritable(self.room.fd, False)  # as the pipe: a role's child process holds none
        return Ring(memory, self.room.fd)


def channel_ends(context: Any) -> tuple[LinkEnd, LinkEnd]:
    """A new channel between two group processes: (the receiver's end, the sender's end)."""
    reader, writer = context.Pipe(duplex=False)
    memory = create_ring_memory()
    room = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
    # Each end its own descriptors: the supervisor closes both ends once the groups have theirs.
    return (LinkEnd(reader, SharedFd(memory), SharedFd(room)),
            LinkEnd(writer, SharedFd(os.dup(memory)), SharedFd(os.dup(room))))


def map_ring(memory_fd: int) -> memoryview:
    """The ring in ``memory_fd`` (a memfd), mapped shared, as a memoryview."""
    return memoryview(mmap.mmap(memory_fd, 0, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE))


class PipeLinks:
    """The links of a group's channels to other groups' processes: a ring and a pipe each.

    Args:
        fds: for each pair with one end here and the other in another group, the
            pipe's file descriptor (the write end for our senders, the read end for
            our receivers).
        rings: the pairs' rings (a pair without one carries its frames in the pipe).
    """

    @classmethod
    def from_ends(cls, ends: Mapping[tuple[str, str], LinkEnd], spin: SpinPolicy | None = None) -> PipeLinks:
        """The links of a group's process from the ends the supervisor sent it."""
        return cls({pair: end.fileno() for pair, end in ends.items()},
                   {pair: end.ring() for pair, end in ends.items()}, spin)

    def __init__(self, fds: Mapping[tuple[str, str], int], rings: Mapping[tuple[str, str], Ring] | None = None,
                 spin: SpinPolicy | None = None) -> None:
        self.fds = dict(fds)
        self.rings = dict(rings or {})
        self.spin = spin  # the group's spin then park (anodize._transport.spin), or None
        # Rung when the run stops: every pipe reader polls it (never drained: stop is final).
        self.wake_fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self._failure_listeners: dict[str, list[int]] = {}  # sender -> its readers' notice eventfds
        self._incoming: dict[tuple[str, str], int] = {}

    def pairs(self, local_roles: Collection[str], channels: Iterable[tuple[str, str]],
              dead: Mapping[str, str]) -> list[tuple[str, str]]:
        """The pairs we were given a pipe for."""
        return list(self.fds)

    def writer(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> PipeSender:
        return PipeSender(self.fds[pair], codec, network, *pair, ring=self.rings.get(pair), wake_fd=self.wake_fd)

    def reader(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> PipeReceiver:
        receiver = PipeReceiver(self.fds[pair], codec, network, pair[0], self.wake_fd, ring=self.rings.get(pair))
        receiver.spin = None if self.spin is None else self.spin.spinner()
        self._incoming[pair] = self.fds[pair]
        self._failure_listeners.setdefault(pair[0], []).append(receiver.notice_fd)
        return receiver

    def silence(self, pair: tuple[str, str]) -> None:
        if pair in self._incoming:
            ring = self.rings.get(pair)
            if ring is not None:  # its next write fails; a waiting one is woken to see it
                ring_close(ring.memory)
                with contextlib.suppress(BlockingIOError):  # full (the sender holds it too): it wakes anyway
                    os.eventfd_write(ring.room_fd, 1)
            _silence(self._incoming[pair])  # its blocked senders get EPIPE

    def noted_failed(self, role: str) -> None:
        for fd in self._failure_listeners.get(role, ()):
            os.eventfd_write(fd, 1)

    def wake(self) -> None:
        os.eventfd_write(self.wake_fd, 1)

    def close(self, linger: float) -> None:
        """Nothing to flush: what was written is in the pipe."""


class PipeSender(WritingEnd):
    """The write end of a channel to a role in another process."""

    read_where = "in the receiver's process"

    def __init__(self, fd: int, codec: Codec, network: LinkNetwork, sender: str, receiver: str,
                 ring: Ring | None = None, wake_fd: int | None = None) -> None:
        self.fd = fd
        self.ring = ring
        self._wake_fd = wake_fd
        self.codec = codec
        self.network = network
        self.sender = sender
        self.receiver = receiver
        # Every frame is written holding this lock, so that none (nor a failure frame written from
        # another thread) lands inside another that takes several writes.
        self._lock: Any = threading.Lock()
        self.closed = False
        if ring is None:
            _grow_pipe(fd)
        else:  # the pipe carries doorbells only: a full one has woken the receiver already
            os.set_blocking(fd, False)
        self._small: Any = None
        if SmallFrameWriter is not None:
            # Compiled (frames.py): messages without a payload or with a small int, whose frame
            # the codec has built once, are written in C (into the ring, when it has room); it
            # hands every other item to put_python. Its lock is the channel's lock.
            self._small = self._lock = SmallFrameWriter(fd, *codec.small_frames(), self.put_python,
                                                        None if ring is None else ring.memory)
            self.put = self._small  # type: ignore[method-assign]
        self._lend: Callable[[], AbstractContextManager[None]] | None = None

    @property
    def lend_while_full(self) -> Callable[[], AbstractContextManager[None]] | None:
        """Set by the sender's endpoint under priority inheritance: the context in which a write
        that must wait for room in the ring (or the pipe) lends the sender's priority
        (anodize._session.inheriting). A pipe's write then first tries without waiting (``RWF_NOWAIT``),
        a ring's never waits while it has room: no extra call on the fast path."""
        return self._lend

    @lend_while_full.setter
    def lend_while_full(self, lend: Callable[[], AbstractContextManager[None]] | None) -> None:
        self._lend = lend
        if self._small is not None:
            self._small.lend = lend

    def put_python(self, item: object) -> None:
        """:meth:`put` in Python: the reference, and the compiled writer's fallback."""
        PipeSender.put(self, item)

    def put(self, item: object) -> None:
        """Send ``(label, payload)``, or a :class:`PeerFailure` telling the receiver why we stop.

        Raises:
            PayloadError: the payload cannot travel (nothing was sent).
            PeerFailedError: the receiver's process is gone.
        """
        if type(item) is tuple:
            try:
                frame = self.codec.message_frame(item[0], item[1])
            except EncodeError as error:
                raise PayloadError(f"role {self.sender}: cannot send {item[0]} to {self.receiver}: "
                                   f"{error}") from None
            except BrokenPipeError:  # waiting for a shared-memory slot, the receiver went away
                raise self._peer_gone() from None
        elif isinstance(item, PeerFailure):
            frame = Codec.failure_frame(_fitted(item.cause))
        else:
            return  # STOP is local to each process
        self._write(frame)

    def put_many(self, items: list[tuple[str, object]]) -> None:
        """Send several ``(label, payload)`` with one write (in pieces of at most 1 MiB).

        A frame whose payload took a shared-memory slot is written at once, with those
        before it: a slot counts as in flight from then on, and a batch holding more arrays
        than the ring has slots would otherwise wait for slots that only its own unwritten
        frames could free.

        Raises:
            PayloadError, PeerFailedError: as :meth:`put`; the messages before the one that
                failed are sent, and the exception's ``sent_in_batch`` says how many.
        """
        frames: list[bytes] = []
        size = sent = 0

        def flush() -> None:
            nonlocal frames, size, sent
            self._write(b"".join(frames))
            sent += len(frames)
            frames, size = [], 0

        try:
            index = 0
            while index < len(items):
                if self._small is not None:  # a run of small messages, compiled: in order, after those before
                    if frames:
                        flush()
                    taken, failed = self._small.write_many(items, index)  # holding the lock for each write
                    sent += taken
                    index += taken
                    if failed:
                        raise self._peer_gone()
                    if index == len(items):
                        break
                label, payload = items[index]
                index += 1
                slots_before = self._slots_used()
                try:
                    frame = self.codec.message_frame(label, payload)
                except EncodeError as error:
                    flush()
                    raise PayloadError(f"role {self.sender}: cannot send {label} to {self.receiver}: "
                                       f"{error}") from None
                except BrokenPipeError:
                    raise self._peer_gone() from None
                frames.append(frame)
                size += len(frame)
                # A batch no bigger than the pipe (the receiver starts on it sooner); an array in a slot now.
                if size >= _PIPE_SIZE or self._slots_used() != slots_before:
                    flush()
            flush()
        except (AnodizeError, RoleStopped) as error:
            error.sent_in_batch = sent  # type: ignore[union-attr]
            raise

    def _slots_used(self) -> int:
        """How many arrays this channel has put in shared-memory slots so far."""
        ring = self.codec.ring
        return 0 if ring is None else ring.arrays_sent

    def _write(self, data: bytes) -> None:
        if not data:
            return
        if self.ring is not None:
            self._write_ring(self.ring, data)
            return
        with self._lock:
            try:
                if self._lend is None:
                    written = os.write(self.fd, data)  # one call for all but huge frames
                else:
                    written = _write_nowait(self.fd, data)
                    if written != len(data):  # the pipe is full: lend while the rest waits for room
                        with self._lend():
                            _write_all(self.fd, data[written:])
                        return
                if written != len(data):
                    _write_all(self.fd, data[written:])
            except OSError:
                raise self._peer_gone() from None

    def _write_ring(self, ring: Ring, data: bytes) -> None:
        """Put ``data`` in the ring, in pieces when it is larger than the room; wait for room."""
        view = memoryview(data)
        with self._lock:
            while view:
                if ring_closed(ring.memory):
                    raise self._peer_gone()
                try:
                    written = ring_write(ring.memory, view)
                except ValueError:  # the receiver broke the indices: it is not a peer to wait for
                    ring_close(ring.memory)
                    raise self._peer_gone() from None
                if written:
                    view = view[written:]
                    self._ring_bell(ring)
                elif self._lend is None:
                    self._wait_for_room(ring)
                else:
                    with self._lend():
                        self._wait_for_room(ring)

    def _ring_bell(self, ring: Ring) -> None:
        """Wake the receiver if it sleeps (the tail is published: see anodize._transport.ring)."""
        if doorbell_due(ring.memory):
            try:
                os.write(self.fd, b"\0")
            except BlockingIOError:  # a pipe full of doorbells: the receiver has been woken
                pass
            except OSError:  # no reader: the receiver's process is gone, or its role silenced
                ring_close(ring.memory)
                raise self._peer_gone() from None

    def _wait_for_room(self, ring: Ring) -> None:
        """Sleep until the receiver frees room, goes away, or the run stops."""
        set_flag(ring.memory, WAITING, 1)
        try:
            if ring_room(ring.memory) or ring_closed(ring.memory):  # freed before the flag was seen
                return
            poller = select.poll()
            poller.register(ring.room_fd, select.POLLIN)
            poller.register(self.fd, 0)  # POLLERR when the read end has gone
            if self._wake_fd is not None:
                poller.register(self._wake_fd, select.POLLIN)
            while True:
                events = dict(poller.poll(int(_ROOM_CHECK * 1000)))
                if events.get(self.fd, 0) & (select.POLLERR | select.POLLHUP):
                    ring_close(ring.memory)
                    return
                if self.network.stopping or self.receiver in self.network.failed:
                    raise self._peer_gone()
                if ring.room_fd in events or ring_room(ring.memory):
                    with contextlib.suppress(BlockingIOError):
                        os.eventfd_read(ring.room_fd)
                    return
        except ValueError:  # broken indices: the next write says so
            return
        finally:
            take_flag(ring.memory, WAITING)

    def buffer(self, shape: tuple[int, ...], dtype: object, strict: bool = False) -> object:
        """A numpy array in a shared-memory slot of this channel, to fill and send (``strict``:
        handed over by making its pages read-only here)."""
        ring = self.codec.ring
        if ring is None:
            import numpy as np

            return np.empty(shape, dtype)  # type: ignore[call-overload]
        return ring.claim_array(shape, dtype, strict)

    def put_failure(self, cause: str) -> None:
        """Best effort, from another thread: tell the receiver this sender failed."""
        if self._lock.acquire(timeout=1.0):  # a writer blocked on a full pipe must not block us
            try:
                frame = Codec.failure_frame(_fitted(cause))
                if self.ring is not None:  # whole or not at all: the supervisor's word comes anyway
                    if not ring_closed(self.ring.memory) and ring_room(self.ring.memory) >= len(frame):
                        ring_write(self.ring.memory, frame)
                        if doorbell_due(self.ring.memory):
                            with contextlib.suppress(OSError):
                                os.write(self.fd, b"\0")
                    return
                _write_all(self.fd, frame)
            except (OSError, ValueError):  # ValueError: the ring's indices are broken
                pass
            finally:
                self._lock.release()

    def _peer_gone(self) -> BaseException:
        if self.network.stopping:  # the receiver stopped with the run: so do we
            return RoleStopped(f"interrupted sending to {self.receiver}")
        cause = self.network.wait_for_cause(self.receiver, "its group's process has ended")
        if cause is None:  # the run stopped meanwhile, and the receiver did not fail
            return RoleStopped(f"interrupted sending to {self.receiver}")
        return PeerFailedError(self.sender, self.receiver, cause)


class PipeReceiver:
    """The read end of a channel from a role in another process (one reading thread)."""

    # Priority inheritance: set by the receiver's endpoint (anodize._session.inheriting), entered
    # only when a receive must wait for the pipe.
    lend_while_empty: Callable[[], AbstractContextManager[None]] | None = None

    # Set by the group's spin policy: wait awake a little before sleeping (see :meth:`ready`).
    spin: Spin | None = None

    def __init__(self, fd: int, codec: Codec, network: LinkNetwork, sender: str, wake_fd: int,
                 ring: Ring | None = None) -> None:
        self.fd = fd
        self.ring = ring
        self._ring_broken = False  # the sender's indices were impossible: nothing more is read from it
        self.codec = codec
        self.network = network
        self.sender = sender
        self._buffer = bytearray()
        self._at = 0
        self.frame_size = 0  # bytes of the last frame taken (a bridge's queue is bounded by these)
        self._pushed: deque[object] = deque()  # sentinels put back so later receives see them too
        self._ready: deque[tuple[object, int]] = deque()  # small messages decoded in a run, with frame sizes
        self._eof = False
        self._poll = select.poll()
        # Rung by the supervisor's word that the sender failed: a forked child of the sender's
        # group may keep the pipe's write end open, so end-of-file alone cannot be waited for.
        self.notice_fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self._poll.register(fd, select.POLLIN)
        self._poll.register(wake_fd, select.POLLIN)
        self._poll.register(self.notice_fd, select.POLLIN)

    def put(self, item: object) -> None:
        """Put back a sentinel (a failure or STOP) for the next receive."""
        self._pushed.append(item)

    def get(self, timeout: float | None = None) -> object:
        """The next message ``(label, payload)``, or a sentinel.

        Raises:
            queue.Empty: nothing arrived within ``timeout`` seconds.
        """
        if self._ready and not self._pushed:  # the commonest case first: a message decoded already
            item, self.frame_size = self._ready.popleft()
            return item
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            if self._pushed:
                return self._pushed.popleft()
            frame = self._next_frame()
            if frame is not None:
                return frame
            if self.network.stopping:
                return STOP
            if self._eof:
                cause = self.network.wait_for_cause(self.sender, "its group's process ended")
                if cause is None:
                    return STOP  # the sender's group ended because the run is stopping
                return PeerFailure(self.sender, cause)
            failed = self.network.failed.get(self.sender)
            if failed is not None:
                if not self._fill(0):  # all it wrote before failing is read
                    return PeerFailure(self.sender, failed)
                continue  # decode what that read brought before waiting for more
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            if self.spin is not None and self.ring is None and left != 0 and self.spin.wait(self._readable, left):
                left = 0  # it came while spinning: read it without sleeping (a ring's receiver spins in _fill_ring)
            lend = self.lend_while_empty
            if lend is not None and left != 0:
                filled = self._fill(0)  # what the pipe holds now, without waiting
                if not filled:  # it will block: lend while it does
                    with lend():
                        filled = self._fill(left)
            else:
                filled = self._fill(left)
            if not filled and deadline is not None and time.monotonic() >= deadline:
                raise Empty

    def get_nowait(self) -> object:
        return self.get(timeout=0)

    def take_ready(self, limit: int) -> list[tuple[str, object]]:
        """Up to ``limit`` small messages already read and decoded, without waiting (none while a
        sentinel waits: it comes first)."""
        if self._pushed:
            return []
        ready = self._ready
        if not ready:
            self._at = self.codec.decode_run(self._buffer, self._at, ready)
        if not ready:
            return []
        if len(ready) <= limit:  # all of them, at the speed of C
            entries = list(ready)
            ready.clear()
        else:
            entries = [ready.popleft() for _ in range(limit)]
        self.frame_size = entries[-1][1]
        return list(map(_MESSAGE, entries))  # the messages without their frame sizes, in C

    def give_back(self, items: list[tuple[str, object]]) -> None:
        """Put messages taken with :meth:`take_ready` back, first in line, in order."""
        self._ready.extendleft((item, 0) for item in reversed(items))

    def empty(self) -> bool:
        """True when no complete frame (nor end-of-file, nor a stop) is waiting."""
        if self._pushed or self._complete() or self._eof or self.network.stopping:
            return False
        return not (self._fill(0) and (self._complete() or self._eof))

    def _readable(self) -> bool:
        """Whether the pipe (or a stop, or a failure notice) can be read now: the spinner's probe."""
        return bool(self._poll.poll(0))

    def _complete(self) -> bool:
        if self._ready:
            return True
        buffer, at = self._buffer, self._at
        if len(buffer) - at < 4:
            return False
        length: int = HEADER.unpack_from(buffer, at)[0]
        return len(buffer) - at - 4 >= length

    def _next_frame(self) -> object | None:
        ready = self._ready
        if not ready:
            self._at = self.codec.decode_run(self._buffer, self._at, ready)
        if ready:
            item, self.frame_size = ready.popleft()
            return item
        buffer, at = self._buffer, self._at
        if len(buffer) - at < 4:
            return None
        (length,) = HEADER.unpack_from(buffer, at)
        if length > MAX_FRAME:  # never buffer that much for one message; the stream is lost
            corrupt = Corrupt(f"a frame of {length} bytes, over the {MAX_FRAME} byte limit")
            self._pushed.append(corrupt)
            return corrupt
        end = at + 4 + length
        if len(buffer) < end:
            return None
        body = buffer[at + 4:end]
        self._at = end
        self.frame_size = 4 + length
        try:
            kind, value = self.codec.decode_body(body)
        except DecodeError as error:  # the stream is still in step: later frames may be fine
            return Corrupt(str(error))
        if kind == FrameKind.FAILURE:
            failure = PeerFailure(self.sender, value)
            self.network.note_failed(self.sender, value)
            return failure
        message: tuple[str, object] = value  # (label, payload)
        return message

    def ready(self) -> bool:
        """True when the ring holds bytes not yet read: cheap (two loads), for a spinning wait."""
        return self.ring is not None and ring_ready(self.ring.memory)

    def _take_ring(self, ring: Ring) -> bool:
        """Copy what the ring holds (``_RING_READ`` at most, ``_READ_SIZE`` inside a larger frame) after the
        unread bytes; True if any came."""
        if self._ring_broken:
            return False
        if self._at > 4 * _RING_READ:  # drop what was consumed now and then, not on every frame
            del self._buffer[:self._at]
            self._at = 0
        limit = _RING_READ
        buffer, at = self._buffer, self._at
        if len(buffer) - at >= 4 and HEADER.unpack_from(buffer, at)[0] > _RING_READ:
            limit = _READ_SIZE  # the rest of a large frame: no objects to build, fewer wakes of its sender
        try:
            return ring_read(ring.memory, buffer, limit, ring.room_fd) > 0
        except ValueError as error:  # the sender's indices are impossible: the stream is lost
            self._ring_broken = True  # the pipe still says when the sender's process ends
            self._pushed.append(Corrupt(f"the channel's ring from {self.sender}: {error}"))
            return True

    def _fill_ring(self, ring: Ring, timeout: float | None) -> bool:
        """:meth:`_fill` with a ring: the frames come from it, the pipe only wakes us."""
        if self._take_ring(ring):
            return True
        if timeout != 0:
            spin = self.spin
            if spin is not None and spin.wait(self.ready, timeout):
                return self._take_ring(ring)
            set_flag(ring.memory, SLEEPING, 1)  # then the tail again: see anodize._transport.ring
            if self._take_ring(ring):
                set_flag(ring.memory, SLEEPING, 0)
                return True
        ready = self._poll.poll(None if timeout is None else max(0, int(timeout * 1000)))
        if timeout != 0:
            set_flag(ring.memory, SLEEPING, 0)
        if any(fd == self.notice_fd for fd, _ in ready):
            with contextlib.suppress(BlockingIOError):
                os.eventfd_read(self.notice_fd)  # the caller now sees the failure in network.failed
        if any(fd == self.fd for fd, _ in ready):
            try:
                bells = os.read(self.fd, _READ_SIZE)  # doorbells: their number says nothing
            except OSError:  # the descriptor was silenced (our role failed): nothing more comes
                bells = b""
            if not bells and not self._take_ring(ring):  # the sender's end is closed, all it wrote read
                self._eof = True
                return True
        return self._take_ring(ring)

    def _fill(self, timeout: float | None) -> bool:
        """Read what the pipe holds, waiting up to ``timeout``; False if no data came.

        Also returns (False) when woken by a stop, so the caller looks again.
        """
        if self.ring is not None:
            return self._fill_ring(self.ring, timeout)
        ready = self._poll.poll(None if timeout is None else max(0, int(timeout * 1000)))
        if any(fd == self.notice_fd for fd, _ in ready):
            with contextlib.suppress(BlockingIOError):
                os.eventfd_read(self.notice_fd)  # the caller now sees the failure in network.failed
        if not any(fd == self.fd for fd, _ in ready):
            return False
        try:
            data = os.read(self.fd, _READ_SIZE)
        except OSError:  # the descriptor was silenced (our role failed): nothing more comes
            data = b""
        if not data:
            self._eof = True
            return True
        if self._at > 4 * _READ_SIZE:  # drop what was consumed now and then, not on every frame
            del self._buffer[:self._at]
            self._at = 0
        self._buffer += data
        return True


def _fitted(cause: str) -> str:
    """``cause`` shortened, visibly, to fit a failure frame in one write."""
    if len(cause) <= _CAUSE_CHARS:
        return cause
    cut = " [... cut to fit one write]"
    return cause[:_CAUSE_CHARS - len(cut)] + cut


def _silence(fd: int) -> None:
    """Close a pipe's read end without freeing its number (a reader may still poll it)."""
    null = os.open(os.devnull, os.O_RDONLY)
    try:
        os.dup2(null, fd)
    finally:
        os.close(null)


def _write_nowait(fd: int, data: bytes) -> int:
    """Write what fits in the pipe now, without waiting (``RWF_NOWAIT``); the bytes written."""
    try:
        return os.pwritev(fd, [data], -1, os.RWF_NOWAIT)
    except BlockingIOError:
        return 0
    except OSError as error:
        if error.errno in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):  # no RWF_NOWAIT here: plain write
            return os.write(fd, data)
        raise


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        written = os.write(fd, view)
        view = view[written:]


def _grow_pipe(fd: int) -> None:
    import fcntl

    # Refused or not on this system: the default size works, only with more blocking.
    with contextlib.suppress(OSError, AttributeError):
        fcntl.fcntl(fd, fcntl.F_SETPIPE_SZ, _PIPE_SIZE)
