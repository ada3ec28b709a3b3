"""The writing end of a Zenoh channel: numbered samples, credit-bounded puts, resends.

Each sample carries its number and the writer's id in its attachment, the first one the
writer's claim too (:mod:`.identity`). A put that finds the channel idle (none for
:data:`~.flow.IDLE` seconds) goes ``express``, at once; the puts of a stream are left to
Zenoh to batch.
A put waits while the receiver's credits (:mod:`.flow`) say its window is full. Every
sample stays kept until the receiver acknowledges it (at most a window of them, so memory
stays bounded); when the acknowledgement does not move for a while, what is kept is sent
again (a router that restarted lost it; the receiver drops what it already has). A
receiver whose reader token is gone for longer than the run's grace fails the send.
"""

from __future__ import annotations

import threading
import time
from collections import deque

from ..._session.channel import PeerFailure
from ...errors import AnodizeError, PeerFailedError, RoleStopped
from ..codec import Codec, EncodeError
from ..links import LinkNetwork, PayloadError, WritingEnd
from .binding import Sample, ZError, payload_of, publisher, subscribe, undeclare
from .flow import CREDIT, IDLE, POLL, RESEND, WINDOW_BYTES, window_for
from .identity import Claim, attachment, new_writer_id
from .ros_topics import RosPublisher
from .session import GroupSession

__all__ = ["ZenohSender"]


class ZenohSender(WritingEnd):
    """The writing end of a channel to a role in another group, over Zenoh."""

    def __init__(self, group: GroupSession, codec: Codec, network: LinkNetwork, sender: str, receiver: str) -> None:
        self.codec = codec
        self.network = network
        self.group = group
        self.sender = sender
        self.receiver = receiver
        settings = group.settings
        self.writer_id = new_writer_id()
        self.claim = Claim(settings.claim_run, group.name, group.incarnation, settings.host, self.writer_id)
        key = settings.channel_key(sender, receiver)
        self._publisher = publisher(group.session, key)
        # The same key, sent at once: for a put that finds the channel idle (a request, a
        # ping-pong, a slow sensor), where Zenoh's batching would only add latency.
        self._express = publisher(group.session, key, express=True)
        self._last_put = 0.0
        self._reader_stem = settings.end_key("reader", sender, receiver, settings.group_of[receiver],
                                             group.incarnation, "").rstrip("/")
        self.reader_id: bytes | None = None  # the receiver's end, chosen at the start barrier
        self._lock = threading.Lock()  # one put at a time; a resend does not interleave with a put
        self._credit = threading.Condition()
        self.written = 0    # samples put (numbered from 0)
        self.taken = 0      # of those, how many the receiver has handed on (its credit)
        self.acked = 0      # of those, how many it has received in order
        self._acked_at = time.monotonic()  # when the acknowledgement last moved (or we last resent)
        self.kept: deque[tuple[int, bytes]] = deque()  # (number, frame) not acknowledged yet
        self._in_flight: deque[int] = deque()  # the sizes of the samples not handed on yet (the byte window)
        self._in_flight_bytes = 0
        self.resent = 0
        self.ros: dict[str, RosPublisher] = {}  # label -> its ROS topic's publisher (set by the links)
        self.window = window_for(network.capacities.get((sender, receiver)))
        self._credits = subscribe(group.session, settings.credit_key(sender, receiver), self._on_credit)
        # The token last: a receiver that sees it finds our credit subscriber declared before it.
        self._token = group.declare(settings.end_key("writer", sender, receiver, group.name, group.incarnation,
                                                     self.writer_id.hex()))

    # ---- credits ---------------------------------------------------------------------------
    def _on_credit(self, sample: Sample) -> None:
        """A credit (on Zenoh's thread): only the accepted receiver's counts (forged credits could
        overrun its memory), never beyond what was written (hostile counts)."""
        data = payload_of(sample)
        if len(data) != CREDIT.size or self.reader_id is None:
            return
        taken, received, reader_id = CREDIT.unpack(data)
        if reader_id != self.reader_id:
            return
        with self._credit:
            written = self.written
            self.taken = max(self.taken, min(taken, written))
            if min(received, written) > self.acked:
                self.acked = min(received, written)
                self._acked_at = time.monotonic()
            self._credit.notify_all()

    def _forget_acked(self) -> None:
        kept, acked = self.kept, self.acked
        while kept and kept[0][0] < acked:
            kept.popleft()
        in_flight, limit = self._in_flight, self.written - self.taken
        while len(in_flight) > limit:
            self._in_flight_bytes -= in_flight.popleft()

    def qsize(self) -> int:
        """Samples put that the receiver has not handed on yet (to within a credit or two)."""
        return self.written - self.taken

    # ---- the Channel protocol --------------------------------------------------------------
    def put(self, item: object) -> None:
        """Send ``(label, payload)``, or a :class:`PeerFailure` saying why we stop.

        Raises:
            PayloadError: the payload cannot travel (nothing was sent).
            PeerFailedError: the receiver is gone (its group ended, or was cut off for longer than the grace).
        """
        if type(item) is tuple:
            lane = self.ros.get(item[0]) if self.ros else None
            try:
                frame = self.codec.message_frame(item[0], item[1])
                cdr = lane.kind.serialize(item[1]) if lane is not None else b""
            except (EncodeError, AnodizeError) as error:
                raise PayloadError(f"role {self.sender}: cannot send {item[0]} to {self.receiver}: "
                                   f"{error}") from None
            with self._lock:
                self._await_credit()
                self._send(frame)
                if lane is not None:  # the label is a ROS topic too: put there as rmw_zenoh does
                    lane.put(cdr)
            return
        if isinstance(item, PeerFailure):
            with self._lock:  # after the last message, outside the window (nothing waits for it)
                self._send(Codec.failure_frame(item.cause))

    def put_failure(self, cause: str) -> None:
        """Best effort, from another thread: tell the receiver this sender failed."""
        if self._lock.acquire(timeout=1.0):
            try:
                self._send(Codec.failure_frame(cause))
            except (ZError, AnodizeError):
                pass
            finally:
                self._lock.release()

    def _send(self, frame: bytes) -> None:
        now = time.monotonic()
        with self._credit:
            number = self.written
            self.written = number + 1
            if not self.kept:  # the wait for its acknowledgement starts now
                self._acked_at = now
            self.kept.append((number, frame))
            self._in_flight.append(len(frame))
            self._in_flight_bytes += len(frame)
        idle = now - self._last_put > IDLE
        self._last_put = now
        (self._express if idle else self._publisher).put(frame, attachment=attachment(number, self.claim))

    def _await_credit(self) -> None:
        """Until the receiver has handed on enough for another sample to fit its window.

        Raises:
            RoleStopped: the run is stopping.
            PeerFailedError: the receiver failed, or is gone.
        """
        with self._credit:
            self._forget_acked()
            if self.written - self.taken < self.window and self._in_flight_bytes < WINDOW_BYTES:
                return
        while True:
            with self._credit:
                self._forget_acked()
                if self.written - self.taken < self.window and self._in_flight_bytes < WINDOW_BYTES:
                    return
                self._credit.wait(POLL)  # releases the GIL
            if self.network.stopping:
                raise RoleStopped(f"interrupted sending to {self.receiver}")
            if self.receiver in self.network.failed:
                raise self._peer_gone()
            self.check_reader()
            self.resend_if_stuck()

    def check_reader(self) -> None:
        """Raise if the receiver's reader token has been gone for longer than the grace."""
        if self.reader_id is None:
            return
        gone = self.group.peers.gone_for(f"{self._reader_stem}/{self.reader_id.hex()}")
        if gone > self.group.grace:
            raise self._peer_gone()

    def resend_if_stuck(self) -> None:
        """Send again what is not acknowledged if the acknowledgement has not moved for a while
        (called by the putting thread while it waits, and by the group's flow thread)."""
        now = time.monotonic()
        with self._credit:
            if not self.kept or now - self._acked_at < RESEND or self.reader_id is None:
                return
            self._acked_at = now
            self._forget_acked()
            again = list(self.kept)
        for number, frame in again:
            self._publisher.put(frame, attachment=attachment(number, self.claim))
        self.resent += len(again)

    def settle(self, linger: float) -> bool:
        """Wait (bounded by ``linger`` seconds) until the receiver has acknowledged everything
        put, sending again what it lacks; False if it did not in time."""
        deadline = time.monotonic() + linger
        while True:
            with self._credit:
                if self.acked >= self.written or self.reader_id is None:
                    return True
                self._credit.wait(POLL)
            if time.monotonic() > deadline or self.network.stopping:
                return False
            try:
                self.check_reader()
            except PeerFailedError:
                return False
            self.resend_if_stuck()

    def find_reader(self) -> bool:
        """Accept the reader of the receiver's group of our incarnation, once its token is there
        (the start barrier): until then nothing is put, so nothing goes only to a reader of an
        incarnation that is ending (a restart), and nothing is missed by the new one.

        Raises:
            SplitBrainError: several readers claim it.
        """
        if self.reader_id is None:
            found = self.group.peers.find(self._reader_stem, f"{self.sender}->{self.receiver}", "reader")
            if found is not None:
                try:
                    self.reader_id = bytes.fromhex(found)
                except ValueError:
                    return False
        return self.reader_id is not None

    def buffer(self, shape: tuple[int, ...], dtype: object, strict: bool = False) -> object:
        """A numpy array to fill and send (Zenoh copies it into the sample anyway)."""
        import numpy as np

        return np.empty(shape, dtype)  # type: ignore[call-overload]

    def close(self) -> None:
        """Undeclare the publisher, the credit subscriber and the writer's token."""
        for entity in (self._credits, self._publisher, self._express, self._token):
            undeclare(entity)

    def _peer_gone(self, why: str = "") -> BaseException:
        cause = self.network.failed.get(self.receiver)
        if cause is None:
            cause = why or (f"its reader went away ({self.group.settings.where(self.receiver)} ended, "
                            f"or was cut off for over {self.group.grace:g} s)")
        return PeerFailedError(self.sender, self.receiver, cause)

