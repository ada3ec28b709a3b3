"""Channels of a group process: in-process queues inside the group, OS pipes between groups.

A group's process sees the same interface as the inproc transport
(:class:`~anodize.transport.inproc.InprocNetwork`): a channel per ordered pair
with ``put``/``get``. Channels to roles of other groups are pipes carrying
frames (:mod:`anodize.transport.codec`); large arrays go through shared-memory rings
(:mod:`anodize.transport.shm`). Only the sending group holds a pipe's write end, so when
that group's process dies the receiver reads end-of-file: a crashed peer is
always noticed, never waited on. A role that fails in a live process has a
failure frame written after its last message, so nothing it sent is lost.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from queue import Empty, SimpleQueue
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from ..errors import AnodizeError, PeerFailedError, RoleStopped
from ..session.channel import STOP, Channel, Corrupt, PeerFailure
from .codec import HEADER, MAX_FRAME, Codec, DecodeError, EncodeError, FrameKind
from .frames import SmallFrameWriter
from .inproc import InprocNetwork
from .shm import ArrayRing

if TYPE_CHECKING:
    from ..ros import RosType

__all__ = ["PipeSender", "PipeReceiver", "ProcessNetwork", "PayloadError", "BridgeQueue", "FailureWriter"]

# Reads of at most 64 KiB: larger ones make malloc mmap and munmap a buffer on every call.
_READ_SIZE = 64 * 1024
_PIPE_SIZE = 1 << 20  # ask the kernel for 1 MiB pipes: fewer blocked senders when streaming
BRIDGE_MESSAGES = 256  # a bridged channel's queue holds at most this many messages...
BRIDGE_BYTES = 4 * 2**20  # ...and this many bytes of frames: then the pipe fills and its sender blocks
# A failure frame stays within PIPE_BUF (4096 bytes; 4 UTF-8 bytes a character at most): one
# write, which a reader sees whole even when the writer dies right after it.
_CAUSE_CHARS = (select.PIPE_BUF - 16) // 4
_EOF_CAUSE_WAIT = 2.0  # seconds to wait for the supervisor's word on why a peer's process ended


@runtime_checkable
class FailureWriter(Protocol):
    """The sending end of a channel to another process: it can say, from any thread, that its role failed."""

    def put_failure(self, cause: str) -> None: ...


class PayloadError(AnodizeError):
    """A payload that cannot cross to another group's process (nothing was sent)."""


class PipeSender:
    """The write end of a channel to a role in another process."""

    def __init__(self, fd: int, codec: Codec, network: ProcessNetwork, sender: str, receiver: str) -> None:
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
                written = os.write(self.fd, data)  # one call for all but huge frames
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

    def __init__(self, fd: int, codec: Codec, network: ProcessNetwork, sender: str) -> None:
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
        self._poll.register(network.wake_fd, select.POLLIN)
        self._poll.register(self.notice_fd, select.POLLIN)
        network.listen_for_failure(sender, self.notice_fd)

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
            if not self._fill(left) and deadline is not None and time.monotonic() >= deadline:
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


class ProcessNetwork(InprocNetwork):
    """The channels of one group's process.

    Args:
        local_roles: the roles running in this process.
        channels: every ordered pair the global type connects.
        pipes: for each pair with one end here and the other in another group, the
            pipe's file descriptor (the write end for our senders, the read end for
            our receivers); a subclass's own link (see ``_writer`` / ``_reader``).
        dead: pairs whose other end cannot be reached (its group did not start with
            this one), with the reason; sending or receiving there fails at once.
        codec_for: builds the codec of a channel (its payload classes and rings).
        doorbell_roles: local roles with parallel branches (their cross-process
            channels are bridged into local queues so ``recv_any`` can wait on all).
    """

    def __init__(self, local_roles: Iterable[str], channels: Iterable[tuple[str, str]],
                 pipes: Mapping[tuple[str, str], Any], dead: dict[str, str],
                 codec_for: Callable[[tuple[str, str]], Codec], doorbell_roles: Iterable[str] = (),
                 capacities: Mapping[tuple[str, str], int] | None = None) -> None:
        self.local_roles = frozenset(local_roles)
        self.capacities = dict(capacities or {})
        local_pairs = [(a, b) for a, b in channels if a in self.local_roles and b in self.local_roles]
        super().__init__(local_pairs, [r for r in doorbell_roles if r in self.local_roles],
                         capacities={pair: n for pair, n in self.capacities.items() if pair in local_pairs})
        self.wake_fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self._cause_arrived = threading.Condition()
        self._failure_listeners: dict[str, list[int]] = {}
        self.bridges: list[threading.Thread] = []
        self.incoming_fds = {pair: fd for pair, fd in pipes.items() if pair[1] in self.local_roles}
        for role, cause in dead.items():
            self.failed[role] = cause
            self.alarm = True
        for (sender, receiver), link in pipes.items():
            codec = codec_for((sender, receiver))
            if sender in self.local_roles:
                self.queues[(sender, receiver)] = self._writer(link, codec, sender, receiver)
            elif receiver in self.doorbells:
                self.queues[(sender, receiver)] = self._bridge(self._reader(link, codec, sender, receiver),
                                                               sender, receiver)
            else:
                self.queues[(sender, receiver)] = self._reader(link, codec, sender, receiver)
        for sender, receiver in channels:  # channels to or from a peer that is not there
            if (sender, receiver) not in self.queues and receiver in self.local_roles:
                gone: SimpleQueue[object] = SimpleQueue()
                gone.put(PeerFailure(sender, dead.get(sender, "not running")))
                self.queues[(sender, receiver)] = gone

    # The two ends of a channel between processes; another transport gives its own.
    def _writer(self, link: Any, codec: Codec, sender: str, receiver: str) -> Channel:
        return PipeSender(link, codec, self, sender, receiver)

    def _reader(self, link: Any, codec: Codec, sender: str, receiver: str) -> Channel:
        return PipeReceiver(link, codec, self, sender)

    def _silence(self, pair: tuple[str, str]) -> None:
        """Our receiver of ``pair`` failed: its blocked senders in other processes must notice."""
        if pair in self.incoming_fds:
            _silence(self.incoming_fds[pair])  # its blocked senders get EPIPE

    def _bridge(self, source: Any, sender: str, receiver: str) -> BridgeQueue:
        """A thread moving frames from a pipe into a local queue, ringing the doorbell.

        The queue is bounded: when the role falls behind, the thread stops reading, the
        pipe fills and the sender blocks (back pressure), as on a channel without a bridge.
        """
        target = BridgeQueue()

        def pump() -> None:
            while True:
                try:
                    item = source.get()
                except MemoryError:
                    raise  # our group's own bound, not the sender's fault: the thread hook reports it
                except Exception as error:  # never die silently: the receiver must hear of it
                    item = Corrupt(f"{type(error).__name__}: {error}")
                    target.put(item)
                    self.ring(receiver, sender)
                    return
                if type(item) is tuple or isinstance(item, Corrupt):
                    target.put_message(item, source.frame_size)  # waits while the queue is full
                else:
                    target.put(item)  # a failure or STOP: never waits
                self.ring(receiver, sender)
                if type(item) is not tuple and not isinstance(item, Corrupt):
                    return  # a failure or STOP ends the channel

        thread = threading.Thread(target=pump, name=f"anodize-bridge:{sender}->{receiver}", daemon=True)
        self.bridges.append(thread)
        return target

    def start(self) -> None:
        for thread in self.bridges:
            thread.start()

    # ---- failure and stop ------------------------------------------------------------------
    def fail(self, role: str, cause: str) -> None:
        """``role`` failed: tell its receivers (a local role), or just record it (a remote one)."""
        if role not in self.local_roles:
            self.note_failed(role, cause)
            return
        with self._lock:
            if role in self.failed:
                return
            self.failed[role] = cause
            self.alarm = True
        for (sender, receiver), channel in self.queues.items():
            if receiver == role:
                self._silence((sender, receiver))
            if sender != role:
                continue
            if isinstance(channel, FailureWriter):
                channel.put_failure(cause)
            else:
                channel.put(PeerFailure(role, cause))
                self.ring(receiver, sender)

    def note_failed(self, role: str, cause: str) -> None:
        """Record why a remote role failed (from its failure frame or the supervisor), and wake
        its receivers here."""
        with self._cause_arrived:
            self.failed.setdefault(role, cause)
            self.alarm = True
            self._cause_arrived.notify_all()
        for fd in self._failure_listeners.get(role, ()):
            os.eventfd_write(fd, 1)

    def listen_for_failure(self, sender: str, fd: int) -> None:
        """Have ``fd`` (an eventfd) written when ``sender`` is noted failed."""
        self._failure_listeners.setdefault(sender, []).append(fd)

    def wait_for_cause(self, role: str, default: str) -> str | None:
        """Why ``role`` failed; wait briefly for the supervisor to say, when its process died.

        Returns:
            The cause (``default`` if none arrived in time), or None when the run is
            stopping and ``role`` did not fail: its process ended with the run.
        """
        with self._cause_arrived:
            self._cause_arrived.wait_for(lambda: role in self.failed or self.stopping, timeout=_EOF_CAUSE_WAIT)
            # Read here, not by the caller: ``stopping`` changes from other threads, and
            # the caller has already seen it False before waiting.
            if self.stopping and role not in self.failed:
                return None
            return self.failed.get(role, default)

    def stop(self) -> None:
        """Wake every receiver of this process with STOP."""
        with self._cause_arrived:  # a receiver waiting to learn why a peer's process ended: the stop
            self.stopping = True
            self.alarm = True
            self._cause_arrived.notify_all()
        for role in self.local_roles:
            self.stop_event_for(role).set()
        os.eventfd_write(self.wake_fd, 1)  # wakes pipe readers; never drained: stop is final
        local = self.local_roles
        for (sender, receiver), channel in self.queues.items():
            # Channels inside this process, whatever wraps them (a bounded queue, a tap), and the
            # queues standing for peers that are not there; pipe ends are woken by wake_fd.
            if (sender in local and receiver in local) or isinstance(channel, SimpleQueue):
                channel.put(STOP)
                self.ring(receiver, sender)


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


def make_codec(classes: Iterable[type], ring: ArrayRing | None,
               read_array: Callable[..., object] | None, ros_types: Iterable[RosType] = ()) -> Codec:
    """A channel's codec: arrays go to ``ring`` when sending, come from ``read_array`` when receiving."""
    return Codec(classes, ring, read_array, ros_types)


class BridgeQueue:
    """A bridged channel's local queue, bounded by message count and frame bytes.

    The bridge thread waits in :meth:`put_message` while the queue is full; signals
    (a failure, STOP, a corrupt frame) and what a receiver puts back go in with
    :meth:`put`, which never waits, so they always get through.

    Args:
        messages: at most this many messages wait...
        budget: ...holding at most this many bytes of frames (one bigger message may
            still wait alone).
    """

    def __init__(self, messages: int = BRIDGE_MESSAGES, budget: int = BRIDGE_BYTES) -> None:
        self._items: deque[tuple[object, int]] = deque()
        self._bytes = 0
        self._messages = messages
        self._budget = budget
        self._lock = threading.Lock()
        self._not_empty = threading.Condition(self._lock)
        self._not_full = threading.Condition(self._lock)

    def put_message(self, item: object, size: int) -> None:
        """Queue a message of ``size`` frame bytes, waiting for room."""
        with self._not_full:
            while self._items and (len(self._items) >= self._messages or self._bytes + size > self._budget):
                self._not_full.wait()
            self._items.append((item, size))
            self._bytes += size
            self._not_empty.notify()

    def put(self, item: object) -> None:
        """Queue a signal (or put one back): never waits."""
        with self._lock:
            self._items.append((item, 0))
            self._not_empty.notify()

    def get(self, *, timeout: float | None = None) -> object:
        """The next item, waiting up to ``timeout`` seconds (None: for ever).

        Raises:
            queue.Empty: nothing arrived in time.
        """
        with self._not_empty:
            if not self._not_empty.wait_for(lambda: self._items, timeout):
                raise Empty
            item, size = self._items.popleft()
            self._bytes -= size
            self._not_full.notify()
            return item

    def get_nowait(self) -> object:
        """The next item, without waiting.

        Raises:
            queue.Empty: nothing is waiting.
        """
        return self.get(timeout=0)

    def empty(self) -> bool:
        """Whether nothing is waiting."""
        return not self._items

    def qsize(self) -> int:
        """How many items wait."""
        return len(self._items)
