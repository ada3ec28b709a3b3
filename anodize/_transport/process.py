"""The process transport's links: OS pipes between group processes.

A group's :class:`~anodize._transport.network.GroupNetwork` links its channels to
roles of other groups with :class:`PipeLinks`: each is a pipe carrying
frames (:mod:`anodize._transport.codec`); large arrays go through shared-memory rings
(:mod:`anodize._transport.shm`). Only the sending group holds a pipe's write end, so when
that group's process dies the receiver reads end-of-file: a crashed peer is
always noticed, never waited on. A role that fails in a live process has a
failure frame written after its last message, so nothing it sent is lost.
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import threading
import time
from collections import deque
from collections.abc import Callable, Collection, Iterable, Mapping
from contextlib import AbstractContextManager
from queue import Empty
from typing import Any

from .._session.channel import STOP, Corrupt, PeerFailure
from ..errors import AnodizeError, PeerFailedError, RoleStopped
from .codec import HEADER, MAX_FRAME, Codec, DecodeError, EncodeError, FrameKind
from .frames import SmallFrameWriter
from .links import LinkNetwork, PayloadError

__all__ = ["PipeLinks", "PipeSender", "PipeReceiver"]

# Reads of at most 64 KiB: larger ones make malloc mmap and munmap a buffer on every call.
_READ_SIZE = 64 * 1024
_PIPE_SIZE = 1 << 20  # ask the kernel for 1 MiB pipes: fewer blocked senders when streaming
# A failure frame stays within PIPE_BUF (4096 bytes; 4 UTF-8 bytes a character at most): one
# write, which a reader sees whole even when the writer dies right after it.
_CAUSE_CHARS = (select.PIPE_BUF - 16) // 4


class PipeLinks:
    """The links of a group's channels to other groups' processes: one pipe each.

    Args:
        fds: for each pair with one end here and the other in another group, the
            pipe's file descriptor (the write end for our senders, the read end for
            our receivers).
    """

    def __init__(self, fds: Mapping[tuple[str, str], int]) -> None:
        self.fds = dict(fds)
        # Rung when the run stops: every pipe reader polls it (never drained: stop is final).
        self.wake_fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self._failure_listeners: dict[str, list[int]] = {}  # sender -> its readers' notice eventfds
        self._incoming: dict[tuple[str, str], int] = {}

    def pairs(self, local_roles: Collection[str], channels: Iterable[tuple[str, str]],
              dead: Mapping[str, str]) -> list[tuple[str, str]]:
        """The pairs we were given a pipe for."""
        return list(self.fds)

    def writer(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> PipeSender:
        return PipeSender(self.fds[pair], codec, network, *pair)

    def reader(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> PipeReceiver:
        receiver = PipeReceiver(self.fds[pair], codec, network, pair[0], self.wake_fd)
        self._incoming[pair] = self.fds[pair]
        self._failure_listeners.setdefault(pair[0], []).append(receiver.notice_fd)
        return receiver

    def silence(self, pair: tuple[str, str]) -> None:
        if pair in self._incoming:
            _silence(self._incoming[pair])  # its blocked senders get EPIPE

    def noted_failed(self, role: str) -> None:
        for fd in self._failure_listeners.get(role, ()):
            os.eventfd_write(fd, 1)

    def wake(self) -> None:
        os.eventfd_write(self.wake_fd, 1)

    def close(self, linger: float) -> None:
        """Nothing to flush: what was written is in the pipe."""


class PipeSender:
    """The write end of a channel to a role in another process."""

    def __init__(self, fd: int, codec: Codec, network: LinkNetwork, sender: str, receiver: str) -> None:
        self.fd = fd
        self.codec = codec
        self.network = network
        self.sender = sender
        self.receiver = receiver
        # Every frame is written holding this lock, so that none (nor a failure frame written from
        # another thread) lands inside another that takes several writes.
        self._lock: Any = threading.Lock()
        self.closed = False
        _grow_pipe(fd)
        self._small: Any = None
        if SmallFrameWriter is not None:
            # Compiled (frames.py): messages without a payload or with a small int, whose frame
            # the codec has built once, are written in C; it hands every other item to put_python.
            # Its lock is the channel's lock.
            self._small = self._lock = SmallFrameWriter(fd, *codec.small_frames(), self.put_python)
            self.put = self._small  # type: ignore[method-assign]
        self._lend: Callable[[], AbstractContextManager[None]] | None = None

    @property
    def lend_while_full(self) -> Callable[[], AbstractContextManager[None]] | None:
        """Set by the sender's endpoint under priority inheritance: the context in which a write
        that must wait for room in the pipe lends the sender's priority (anodize._session.inheriting).
        Every write then first tries without waiting (``RWF_NOWAIT``): no extra call on the fast path."""
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

    def buffer(self, shape: tuple[int, ...], dtype: object) -> object:
        """A numpy array in a shared-memory slot of this channel, to fill and send."""
        ring = self.codec.ring
        if ring is None:
            import numpy as np

            return np.empty(shape, dtype)  # type: ignore[call-overload]
        return ring.claim_array(shape, dtype)

    def put_failure(self, cause: str) -> None:
        """Best effort, from another thread: tell the receiver this sender failed."""
        if self._lock.acquire(timeout=1.0):  # a writer blocked on a full pipe must not block us
            try:
                _write_all(self.fd, Codec.failure_frame(_fitted(cause)))
            except OSError:
                pass
            finally:
                self._lock.release()

    # The read side of the Channel protocol: the receiving process holds the read end.
    def get(self, *, timeout: float | None = None) -> object:
        """Never used: this is the write end of the pipe.

        Raises:
            AnodizeError: always.
        """
        raise AnodizeError(f"the channel {self.sender}->{self.receiver} is read in {self.receiver}'s process")

    def get_nowait(self) -> object:
        """Never used: as :meth:`get`."""
        return self.get()

    def empty(self) -> bool:
        """True: nothing arrives at the write end."""
        return True

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

    def __init__(self, fd: int, codec: Codec, network: LinkNetwork, sender: str, wake_fd: int) -> None:
        self.fd = fd
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
        return [entry[0] for entry in entries]  # type: ignore[misc]

    def give_back(self, items: list[tuple[str, object]]) -> None:
        """Put messages taken with :meth:`take_ready` back, first in line, in order."""
        self._ready.extendleft((item, 0) for item in reversed(items))

    def empty(self) -> bool:
        """True when no complete frame (nor end-of-file, nor a stop) is waiting."""
        if self._pushed or self._complete() or self._eof or self.network.stopping:
            return False
        return not (self._fill(0) and (self._complete() or self._eof))

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

    def _fill(self, timeout: float | None) -> bool:
        """Read what the pipe holds, waiting up to ``timeout``; False if no data came.

        Also returns (False) when woken by a stop, so the caller looks again.
        """
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
