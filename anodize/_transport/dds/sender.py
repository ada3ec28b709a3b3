"""The writing end of a DDS channel: lanes, credit-bounded writes, the receiver's readers watched.

A channel to a role of another group is written on its own topic (codec frames, as
:mod:`.frame` CDR); labels that are ROS 2 topics are written on those, one lane each.
A write waits while the receiver's credits (:mod:`.flow`) say its window is full; a
write that finds no room in Cyclone is retried in short sleeps that release the GIL.
A receiver whose readers are gone (its group ended or was cut off) fails the send.
Writes held back (no room in Cyclone, or no credit) for over a lease in all, or not all
acknowledged at the end, name in the group's report every other reader matched on the
topic: a reliable reader that does not take its samples holds every write back, and only
one in the run's partition (or one subscribed to every partition) can match (:mod:`.settings`).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from ..._session.channel import PeerFailure
from ...errors import AnodizeError, PeerFailedError, RoleStopped
from ..codec import Codec, EncodeError
from ..links import LinkNetwork, PayloadError, WritingEnd
from .binding import (
    ANY_SAMPLE,
    RETCODE_TIMEOUT,
    DataReader,
    DataWriter,
    DDSException,
    ReadCondition,
    WaitSet,
    duration,
    matched_publications,
    matched_subscriptions,
    ref_of,
    take,
    wait_for_acks,
    write,
)
from .flow import COUNT, CREDIT_EVERY, POLL, WINDOW_BYTES, window_for
from .frame import Frame, cdr_sample, ros_sample
from .identity import instance_handle
from .peers import describe, find_peer
from .qos import Endpoints

if TYPE_CHECKING:
    from ..._ros import RosType

__all__ = ["DdsSender", "OutLane"]


class OutLane:
    """One topic a sender writes: the channel's own (codec frames) or a ROS topic (one label's CDR)."""

    def __init__(self, writer: DataWriter[Any], kind: RosType | None, topic: str, lossy: bool = False) -> None:
        self.writer = writer
        self.lossy = lossy  # its QoS may lose messages: outside the credits (nothing would credit a lost one)
        self.ref = ref_of(writer)
        self.kind = kind  # None: the channel's own topic
        self.topic = topic
        self.accepted: int | None = None  # the subscription handle of the receiver's reader (None: any, external)


class DdsSender(WritingEnd):
    """The writing end of a channel to a role in another group, or to an external role (over DDS)."""

    def __init__(self, endpoints: Endpoints, codec: Codec, network: LinkNetwork, sender: str, receiver: str) -> None:
        self.codec = codec
        self.network = network
        self.endpoints = endpoints
        self.sender = sender
        self.receiver = receiver
        settings = endpoints.settings
        self.external = settings.is_external(receiver)  # a ROS node: only ROS topics, no credits
        self._lock = threading.Lock()  # a failure frame must not interleave with a message
        self._next_check = 0.0  # when to look again whether the receiver's readers are still there
        self._held_since: float | None = None  # when this write began to be held back (None: it is not)
        self._held = 0.0  # seconds earlier writes were held back, since the last holders were named
        self._named: set[int] = set()  # the other readers already named as holding writes back
        self.frames: OutLane | None = None
        if not self.external:
            self.frames = OutLane(DataWriter(endpoints.participant, endpoints.topic((sender, receiver)),
                                             qos=endpoints.writer_qos), None, "")
        self.ros: dict[str, OutLane] = {}  # label -> its ROS topic's writer
        if settings.ros is not None:
            for label, topic in settings.ros.channel_topics(sender, receiver).items():
                dds_topic, kind = endpoints.ros_topic(topic)
                profile = settings.ros.qos_of(topic.name)
                self.ros[label] = OutLane(DataWriter(endpoints.participant, dds_topic,
                                                     qos=endpoints.ros_qos(kind, True, profile)), kind, topic.name,
                                          profile.lossy)
        self.lanes = [lane for lane in (self.frames, *self.ros.values()) if lane is not None]
        self.credits: DataReader[Frame] | None = None
        self.credit_writer: int | None = None  # the publication handle of the receiver's credit writer
        if not self.external:
            self.credits = DataReader(endpoints.participant, endpoints.topic((sender, receiver), "/credit"),
                                      qos=endpoints.credit_qos)
            self._credits_ref = ref_of(self.credits)
            self._credit_wait = WaitSet(endpoints.participant)
            self._credit_wait.attach(ReadCondition(self.credits, ANY_SAMPLE))
        self.written = 0  # messages written
        self.taken = 0    # of those, how many the receiver says it has taken
        self.window = window_for(network.capacities.get((sender, receiver)))
        self._credit_look = CREDIT_EVERY  # when put() next reads the credits that came
        self._in_flight: deque[int] = deque()  # the sizes of the samples written but not taken
        self._in_flight_bytes = 0

    def qsize(self) -> int:
        """Messages written that the receiver has not handed on yet, as its credits say (to
        within a credit or two, 32 messages each); into an external role, unknown: 0."""
        return self.written - self.taken

    @property
    def writer(self) -> DataWriter[Any]:
        """The writer of the channel's own topic (or of its first ROS topic, into an external role)."""
        return self.lanes[0].writer

    def put(self, item: object) -> None:
        """Send ``(label, payload)``, or a :class:`PeerFailure` saying why we stop.

        Raises:
            PayloadError: the payload cannot travel (nothing was sent).
            PeerFailedError: the receiver's reader is gone (its group ended or was cut off).
        """
        if type(item) is tuple:
            lane = self.ros.get(item[0]) if self.ros else None
            try:
                sample = (cdr_sample(self.codec.message_frame(item[0], item[1])) if lane is None
                          else ros_sample(lane.kind.serialize(item[1])))  # type: ignore[union-attr]
            except (EncodeError, AnodizeError) as error:
                raise PayloadError(f"role {self.sender}: cannot send {item[0]} to {self.receiver}: "
                                   f"{error}") from None
            counted = self.credits is not None and not (lane is not None and lane.lossy)
            with self._lock:
                if counted and self.written >= self._credit_look:
                    # Read what credits came once every so many writes (a take costs microseconds),
                    # so qsize(), the report's backlog, stays true to within a credit or two.
                    self._credit_look = self.written + CREDIT_EVERY
                    self._take_credits()
                if counted and (self.written - self.taken >= self.window or self._in_flight_bytes >= WINDOW_BYTES):
                    self._await_credit()
                self._write(lane or self.frames, sample)  # type: ignore[arg-type]
                if counted:
                    self.written += 1
                    self._in_flight.append(len(sample))
                    self._in_flight_bytes += len(sample)
            return
        if isinstance(item, PeerFailure) and self.frames is not None:
            with self._lock:
                self._settle_ros_lanes()
                self._write(self.frames, cdr_sample(Codec.failure_frame(item.cause)))

    def _settle_ros_lanes(self, seconds: float = 1.0) -> None:
        """Before a failure frame: what the ROS topics carry has reached the receiver, which
        then finds it there before it reads of the failure on the channel's own topic."""
        for lane in self.ros.values():
            with contextlib.suppress(DDSException):
                wait_for_acks(lane.writer, seconds)

    def _write(self, lane: OutLane, sample: bytes, give_up: float | None = None) -> None:
        pause = 0.0002
        while True:
            # A reader gone since the last look takes what is written meanwhile nowhere;
            # its group is gone too, so this only bounds how soon the sender hears of it.
            now = time.monotonic()
            if now >= self._next_check:
                self._next_check = now + POLL
                self._check_readers()
            ret = write(lane.ref, sample)
            if ret == 0:
                if self._held_since is not None:
                    self._released(now)
                return
            if ret != RETCODE_TIMEOUT:
                raise AnodizeError(f"DDS write on {self.sender}->{self.receiver} failed: {DDSException(ret)}")
            self._next_check = 0.0  # held back: is the receiver still there?
            self._held_back(now, (lane,))
            if self.network.stopping:
                raise RoleStopped(f"interrupted sending to {self.receiver}")
            if self.receiver in self.network.failed:
                raise self._peer_gone()
            if give_up is not None and time.monotonic() > give_up:
                return
            time.sleep(pause)  # releases the GIL: the group's other threads run on
            pause = min(pause * 2, 0.005)

    def _check_readers(self) -> None:
        """Raise if the receiver's reader of any lane is gone (an external role: if no ROS node
        subscribes a topic any more)."""
        for lane in self.lanes:
            matched = matched_subscriptions(lane.writer)
            if lane.accepted is None:
                if self.external and not matched:
                    raise self._peer_gone(f"no ROS 2 node subscribes {lane.topic} any more")
            elif lane.accepted not in {instance_handle(h) for h in matched}:
                raise self._peer_gone()

    def _held_back(self, now: float, lanes: Iterable[OutLane]) -> None:
        """A write is held back (no room in Cyclone, or no credit): once that has added up to
        over a lease, name whoever else reads the lanes. A reliable reader that does not take
        its samples holds every write back, and the receiver's credits with it (Cyclone sends
        on only as fast as every reader acknowledges)."""
        if self._held_since is None:
            self._held_since = now
        elif self._held + now - self._held_since > self.endpoints.settings.lease:
            self._held, self._held_since = 0.0, now
            for lane in lanes:
                self._name_holders(lane, f"writes held back for over {self.endpoints.settings.lease:g} s in all")

    def _released(self, now: float) -> None:
        if self._held_since is not None:
            self._held += now - self._held_since
            self._held_since = None

    def settle(self, linger: float) -> None:
        """Wait (bounded by ``linger`` seconds a lane) until every reader has acknowledged what was
        written, before the process ends; name the other readers of a lane where some did not."""
        for lane in self.lanes:
            with contextlib.suppress(DDSException):
                if not wait_for_acks(lane.writer, linger):
                    self._name_holders(lane, f"what was written was not all acknowledged within {linger:g} s "
                                             "of the end")

    def _name_holders(self, lane: OutLane, what: str) -> None:
        """Name, once each, the readers matched on a lane besides the receiver's: ``what`` happened
        to the writes, so one of them may not take what it is sent."""
        where = f" ({lane.topic})" if lane.kind is not None else ""
        receiver = self.endpoints.settings.where(self.receiver)
        owner = "" if lane.accepted is None else f" besides the reader of {receiver}"
        for handle in matched_subscriptions(lane.writer):
            if instance_handle(handle) in self._named or instance_handle(handle) == lane.accepted:
                continue
            self._named.add(instance_handle(handle))
            stranger = describe(handle, lane.writer.get_matched_subscription_data(handle))
            self.endpoints.report(
                f"{self.sender}->{self.receiver}{where}: {what}, with DDS readers matched there{owner}; one is "
                f"{stranger}: a reliable reader that does not take its samples holds every write back")

    def _await_credit(self) -> None:
        """Until the receiver has taken enough for another sample to fit its window.

        Raises:
            RoleStopped: the run is stopping.
            PeerFailedError: the receiver failed, or its reader is gone.
        """
        while True:
            self._take_credits()
            now = time.monotonic()
            if self.written - self.taken < self.window and self._in_flight_bytes < WINDOW_BYTES:
                self._released(now)
                return
            if self.network.stopping:
                raise RoleStopped(f"interrupted sending to {self.receiver}")
            if self.receiver in self.network.failed:
                raise self._peer_gone()
            self._held_back(now, self.lanes)
            if now >= self._next_check:
                self._next_check = now + POLL
                self._check_readers()
            self._credit_wait.wait(duration(seconds=POLL))  # releases the GIL

    def _take_credits(self) -> None:
        taken = take(self._credits_ref, ANY_SAMPLE, 8)
        if type(taken) is int:
            raise AnodizeError(f"DDS take of credits on {self.sender}->{self.receiver} failed: "
                               f"{DDSException(taken)}")
        for data, info in taken:
            # Only the receiver's own credit writer counts: forged credits could overrun its reader.
            if info.valid_data and instance_handle(info.publication_handle) == self.credit_writer and len(data) >= 16:
                self.taken = max(self.taken, min(COUNT.unpack_from(data, 8)[0], self.written))
        while len(self._in_flight) > self.written - self.taken:
            self._in_flight_bytes -= self._in_flight.popleft()

    def find_reader(self) -> bool:
        """Accept the readers of the receiver's group of our incarnation, if they have matched (the
        start barrier): until then nothing is written, so nothing goes only to a reader of an
        incarnation that is ending (a restart), and nothing is missed by the new one. Into an
        external role: some ROS node subscribes each topic."""
        found = True
        for lane in self.lanes:
            channel = f"{self.sender}->{self.receiver}" + (f" ({lane.topic})" if lane.kind is not None else "")
            matched = matched_subscriptions(lane.writer)
            if self.external:
                found = found and bool(matched)
            elif lane.accepted is None:
                lane.accepted = find_peer(self.endpoints, self.receiver, channel, matched,
                                          lane.writer.get_matched_subscription_data)[0]
                found = found and lane.accepted is not None
        if self.credits is not None and self.credit_writer is None:
            self.credit_writer = find_peer(self.endpoints, self.receiver, f"{self.sender}->{self.receiver} (credits)",
                                           matched_publications(self.credits),
                                           self.credits.get_matched_publication_data)[0]
        return found and (self.credits is None or self.credit_writer is not None)

    def put_failure(self, cause: str) -> None:
        """Best effort, from another thread: tell the receiver this sender failed."""
        if self.frames is not None and self._lock.acquire(timeout=1.0):
            try:
                with contextlib.suppress(AnodizeError, PeerFailedError, RoleStopped):
                    self._settle_ros_lanes()
                    self._write(self.frames, cdr_sample(Codec.failure_frame(cause)), give_up=time.monotonic() + 1.0)
            finally:
                self._lock.release()

    def buffer(self, shape: tuple[int, ...], dtype: object, strict: bool = False) -> object:
        """A numpy array to fill and send (DDS copies it into the sample anyway; ``strict`` changes nothing)."""
        import numpy as np

        return np.empty(shape, dtype)  # type: ignore[call-overload]

    def _peer_gone(self, why: str = "") -> BaseException:
        cause = self.network.failed.get(self.receiver)
        if cause is None:
            cause = why or (f"its reader went away ({self.endpoints.settings.where(self.receiver)} ended, "
                            "or stopped answering, or was cut off)")
        return PeerFailedError(self.sender, self.receiver, cause)
