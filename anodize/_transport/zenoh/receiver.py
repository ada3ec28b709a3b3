"""The reading end of a Zenoh channel: samples of the accepted writer, in order, credited.

Samples wait in the subscriber's ring (:func:`.binding.subscribe_pulled`): Zenoh's thread
neither calls Python nor takes the GIL for them. The role's thread pulls them when it
reads (a batch at a time; it waits in ``recv()``, releasing the GIL, when none is there),
and the group's flow thread pulls them while the role is busy elsewhere, so they are
acknowledged and the ring does not fill (a full ring drops its oldest: a gap, sent again).
Each sample's attachment is checked (:mod:`.identity`): a sample of any writer but the one
chosen at the start barrier is dropped, counted and reported; a number already received is
a duplicate (a resend) and dropped; a number past the next expected one (a gap: a router
lost what came between) is dropped too, and the sender sends it all again. So the queue
holds samples in order, at most a window of them (the sender's credits), and memory stays
bounded whatever the network sends (the ring holds at most :data:`RING` samples more).
Credits (:mod:`.flow`) count what is handed on to the role and acknowledge what was
received. A writer whose token is gone for longer than the grace ends the channel with a
:class:`~anodize._session.channel.PeerFailure`, after everything it put has been read.
A reading thread waiting in ``recv()`` is woken by an empty sample put on the channel's
key to this session alone (:meth:`ZenohReceiver.wake`): by the run stopping, a failure
noted, or the flow thread (the writer lost, a timed read's deadline near: its last two
ticks are spent looking into the ring every millisecond).
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections import deque
from queue import Empty

from ..._session.channel import STOP, Corrupt, PeerFailure
from ..codec import HEADER, MAX_FRAME, Codec, DecodeError, FrameKind
from ..links import LinkNetwork
from .binding import Sample, ZError, local_publisher, payload_of, publisher, subscribe_pulled, undeclare
from .flow import CREDIT, CREDIT_BYTES, POLL, TICK, WINDOW, credit_every_for
from .identity import claim_of, new_writer_id, parse_attachment
from .session import GroupSession

__all__ = ["ZenohReceiver"]

_REPORTED = 8  # foreign writers named in the report, at most (each is counted)
RING = 2 * WINDOW + 32  # samples the subscriber's ring holds: a window, its resends, wakes
_NAP = 0.001  # seconds between looks into the ring while a read with a timeout waits


class ZenohReceiver:
    """The reading end of a channel from a role in another group, over Zenoh (one reading thread)."""

    def __init__(self, group: GroupSession, codec: Codec, network: LinkNetwork, sender: str, receiver: str) -> None:
        self.codec = codec
        self.network = network
        self.group = group
        self.sender = sender
        self.receiver = receiver
        settings = group.settings
        self.reader_id = new_writer_id()
        self._writer_stem = settings.end_key("writer", sender, receiver, settings.group_of[sender],
                                             group.incarnation, "").rstrip("/")
        self.writer_id: bytes | None = None  # the sender's end, chosen at the start barrier
        self._lock = threading.Lock()  # the ring is read by one thread at a time; the counts with it
        self._waiting = False  # the reading thread is in recv(): no one else may touch the ring
        self._wake_at = math.inf  # while it waits: when the flow thread wakes it (a timed read)
        self._closed = False
        self.samples: deque[bytes] = deque()
        self.received = 0   # samples received in order (the next expected number)
        self.taken = 0      # of those, handed on to the role
        self.credited = (0, 0)  # the counts last told to the sender
        self.credit_every = credit_every_for(network.capacities.get((sender, receiver)))
        self._uncredited_bytes = 0
        self.duplicates = 0
        self.gaps = 0
        self.frame_size = 0
        self._pushed: deque[object] = deque()
        self._lost: str | None = None
        self.rejected: dict[bytes, int] = {}  # foreign writer id -> samples dropped (b"*": beyond the first few)
        self._credit_lock = threading.Lock()
        self._credits = publisher(group.session, settings.credit_key(sender, receiver))
        key = settings.channel_key(sender, receiver)
        self._subscriber = subscribe_pulled(group.session, key, RING)
        self._waker = local_publisher(group.session, key)
        self._wake_lock = threading.Lock()
        self.ticked = False  # a flow thread calls tick() (the links set it): recv() may wait unbounded
        # The token last: a sender that sees it finds our subscriber declared before it.
        self._token = group.declare(settings.end_key("reader", sender, receiver, group.name, group.incarnation,
                                                     self.reader_id.hex()))

    # ---- samples, pulled from the ring --------------------------------------------------------
    def _pull(self) -> None:
        """Take every sample waiting in the ring (the caller holds the lock, and no one waits in recv())."""
        if self._closed:
            return  # undeclared
        try_recv = self._subscriber.try_recv
        while (sample := try_recv()) is not None:
            self._on_sample(sample)

    def _on_sample(self, sample: Sample) -> None:
        """One sample from the network (the caller holds the lock)."""
        raw = sample.attachment
        if raw is None and not sample.payload:
            return  # a wake (:meth:`wake`); one from the network only wakes us too
        data = b"" if raw is None else raw.to_bytes()
        parsed = parse_attachment(data)
        if parsed is None or parsed[1] != self.writer_id:
            if self.writer_id is not None or parsed is None:
                self._reject(parsed, data)
            return  # before the barrier: the sender sends again what we did not take
        number = parsed[0]
        if number < self.received:
            self.duplicates += 1
            # A resend of what we have: our credit for it was lost (a router that died with it), and
            # the sender waits for one; the next credit goes out even though our counts did not move.
            self.credited = (-1, -1)
            return
        if number > self.received or len(self.samples) > WINDOW:  # a gap (or a flood): sent again later
            self.gaps += 1
            return
        self.samples.append(payload_of(sample))
        self.received += 1

    def _reject(self, parsed: tuple[int, bytes] | None, data: bytes) -> None:
        """Count a sample of a writer we do not listen to; name the first few such writers in the report."""
        writer, claim = (parsed[1], claim_of(data)) if parsed is not None else (b"", "")
        if writer not in self.rejected:
            if len(self.rejected) >= _REPORTED:
                writer = b"*"  # beyond that many, counted together (the network may make up any number)
            else:
                self.group.report(
                    f"rejected samples on {self.sender}->{self.receiver} from Zenoh writer "
                    f"{writer.hex() or '(no anodize attachment)'} (it claims {claim or 'nothing'!r}); only "
                    f"{self.writer_id.hex() if self.writer_id else '(not chosen yet)'} "
                    f"({self.group.settings.where(self.sender)}) may write there")
        self.rejected[writer] = self.rejected.get(writer, 0) + 1

    # ---- the Channel protocol ---------------------------------------------------------------
    def put(self, item: object) -> None:
        """Put back a sentinel (a failure or STOP) for the next receive."""
        self._pushed.append(item)

    def get(self, timeout: float | None = None) -> object:
        """The next message ``(label, payload)``, or a sentinel.

        Raises:
            queue.Empty: nothing arrived within ``timeout`` seconds.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            if self._pushed:
                return self._pushed.popleft()
            with self._lock:
                if not self.samples:
                    self._pull()
                data = self.samples.popleft() if self.samples else None
            if data is not None:
                return self._hand_on(data)
            if self.network.stopping:
                return STOP
            failed = self.network.failed.get(self.sender)
            if failed is not None:
                return PeerFailure(self.sender, failed)
            lost = self._writer_lost()
            if lost is not None:
                with self._lock:
                    self._pull()
                    if self.samples:  # all it put before going is read first
                        continue
                self.network.note_failed(self.sender, lost)
                return PeerFailure(self.sender, lost)
            if deadline is not None and deadline - time.monotonic() <= 0:
                raise Empty
            self._wait(deadline)

    def _wait(self, deadline: float | None) -> None:
        """Until a sample (or a wake) is in the ring, or about :data:`POLL` passed, or ``deadline``.
        Credits owed meanwhile are the flow thread's to send (within a tick): not one put back per
        message of a ping-pong."""
        now = time.monotonic()
        if not self.ticked or self._closed or (deadline is not None and deadline - now < 2 * TICK):
            # The last ticks of a timed read (or no flow thread to wake us): a look every millisecond.
            end = now + POLL if deadline is None else min(deadline, now + POLL)
            while time.monotonic() < end:
                with self._lock:
                    self._pull()
                    if self.samples:
                        return
                time.sleep(_NAP)
            return
        # The flow thread wakes us two ticks before the deadline at the latest.
        self._wake_at = math.inf if deadline is None else deadline - 2 * TICK
        with self._lock:
            self._pull()
            if self.samples or self._closed:  # (closing: no new wait in the subscriber it undeclares)
                return
            self._waiting = True
        try:
            sample = self._subscriber.recv()  # releases the GIL; woken by wake()
        except ZError:  # undeclared: the channel is closing
            sample = None
        with self._lock:
            self._waiting = False
            if sample is not None:
                self._on_sample(sample)
                self._pull()

    def get_nowait(self) -> object:
        return self.get(timeout=0)

    def empty(self) -> bool:
        """True when nothing (no message, no failure, no stop) is waiting."""
        if self._pushed or self.network.stopping or self.sender in self.network.failed:
            return False
        with self._lock:
            if not self._waiting:
                self._pull()
            return not self.samples

    def qsize(self) -> int:
        """Samples received and not handed on yet."""
        with self._lock:
            if not self._waiting:
                self._pull()
            return len(self.samples)

    def wake(self) -> None:
        """Wake the reading thread if it waits in recv() (a failure noted, the run stopping): an empty
        sample, without attachment, put to this session's subscribers alone."""
        if self._waiting:
            with self._wake_lock, contextlib.suppress(ZError):
                self._waker.put(b"")

    def tick(self) -> None:
        """From the flow thread, every tick: pull what a busy role left in the ring (so it is
        acknowledged, and the ring never fills), or wake a role waiting for a writer that is lost;
        then credit."""
        with self._lock:
            waiting = self._waiting
            if not waiting:
                self._pull()
        if waiting and (self.network.stopping or self.sender in self.network.failed
                        or time.monotonic() >= self._wake_at or self._writer_lost() is not None):
            self.wake()  # (again: one told before the reader began to wait would be missed)
        self.credit()

    def _hand_on(self, data: bytes) -> object:
        """A sample, decoded. Credit counts what is handed on, not what is received, so the
        sender's window covers the samples we hold too (bounded memory)."""
        self.taken += 1
        self._uncredited_bytes += len(data)
        if self.taken - self.credited[0] >= self.credit_every or self._uncredited_bytes >= CREDIT_BYTES:
            self.credit()
        return self._decode(data)

    def credit(self) -> None:
        """Tell the sender how far we have got, if that moved since we last did (from the reading
        thread, and from the group's flow thread for a role that has stopped reading)."""
        with self._credit_lock:
            counts = (self.taken, self.received)
            if counts == self.credited or self.writer_id is None:
                return
            self.credited = counts
            self._uncredited_bytes = 0
            with contextlib.suppress(ZError):  # the session is closing: the sender learns of it from our token
                self._credits.put(CREDIT.pack(counts[0], counts[1], self.reader_id))

    def _decode(self, data: bytes) -> object:
        if len(data) < HEADER.size:
            return Corrupt(f"a Zenoh sample of {len(data)} bytes")
        (length,) = HEADER.unpack_from(data)
        if length != len(data) - HEADER.size or length > MAX_FRAME:
            return Corrupt(f"a Zenoh sample whose frame length {length} does not match its {len(data)} bytes")
        self.frame_size = len(data)
        try:
            kind, value = self.codec.decode_body(memoryview(data)[HEADER.size:])
        except DecodeError as error:
            return Corrupt(str(error))
        if kind == FrameKind.FAILURE:
            self.network.note_failed(self.sender, value)
            return PeerFailure(self.sender, value)
        message: tuple[str, object] = value
        return message

    def _writer_lost(self) -> str | None:
        """Why the accepted writer is gone (its token gone for longer than the grace), or None."""
        if self._lost is None and self.writer_id is not None:
            gone = self.group.peers.gone_for(f"{self._writer_stem}/{self.writer_id.hex()}")
            if gone > self.group.grace:
                self._lost = (f"its Zenoh writer went away: {self.group.settings.where(self.sender)} ended, "
                              f"or stopped answering, or was cut off for over {self.group.grace:g} s")
        return self._lost

    # ---- start barrier ----------------------------------------------------------------------
    def find_writer(self) -> bool:
        """Accept the writer of the expected group of our incarnation, once its token is there.

        Raises:
            SplitBrainError: several writers claim it.
        """
        if self.writer_id is None:
            found = self.group.peers.find(self._writer_stem, f"{self.sender}->{self.receiver}", "writer")
            if found is not None:
                try:
                    writer_id = bytes.fromhex(found)
                except ValueError:
                    return False
                with self._lock:
                    self.writer_id = writer_id
        return self.writer_id is not None

    def close(self) -> None:
        """A last credit, then undeclare the subscriber (once no thread waits in it: bounded), the
        credit publisher and the reader's token."""
        self.credit()
        with self._lock:
            self._closed = True
        deadline = time.monotonic() + 1.0
        while self._waiting and time.monotonic() < deadline:
            self.wake()
            time.sleep(_NAP)
        for entity in (self._subscriber, self._credits, self._waker, self._token):
            undeclare(entity)

