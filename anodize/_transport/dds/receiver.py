"""The reading end of a DDS channel: lanes read in the plan's order, writers admitted, credits given.

Samples are taken as raw CDR from the accepted writer only (chosen at the start
barrier, :mod:`.barrier`); any other writer's samples are dropped, counted and
reported. Credit (:mod:`.flow`) counts what is handed on to the role, so the sender's
window covers what we hold too. A writer whose lease expired or who was deleted ends
the channel with a :class:`~anodize._session.channel.PeerFailure`, after everything it
wrote has been read.
"""

from __future__ import annotations

import time
from collections import deque
from queue import Empty
from typing import TYPE_CHECKING, Any

from ..._session.channel import STOP, Corrupt, PeerFailure
from ...errors import AnodizeError
from ..codec import HEADER, MAX_FRAME, Codec, DecodeError, FrameKind
from ..links import LinkNetwork
from ..ros_lanes import LanePlan
from .binding import (
    ANY_SAMPLE,
    DataReader,
    DataWriter,
    DDSException,
    ReadCondition,
    WaitSet,
    duration,
    matched_publications,
    ref_of,
    take,
    userdata_of,
    write,
)
from .flow import COUNT, CREDIT_BYTES, POLL, TAKE, credit_every_for
from .frame import LENGTH, Frame, cdr_sample
from .identity import instance_handle, parse_identity, userdata_fields
from .peers import find_peer
from .qos import Endpoints

if TYPE_CHECKING:
    from ..._ros import RosType

__all__ = ["DdsReceiver", "InLane"]


class InLane:
    """One topic a receiver reads: the channel's own (codec frames) or a ROS topic (one label)."""

    def __init__(self, reader: DataReader[Any], label: str | None, kind: RosType | None, topic: str,
                 lossy: bool = False) -> None:
        self.reader = reader
        self.lossy = lossy  # its QoS may lose messages: outside the credits (the sender does not count it)
        self.ref = ref_of(reader)
        self.label = label  # the one label a ROS topic carries (None: the channel's own topic)
        self.kind = kind
        self.topic = topic
        self.samples: deque[bytes | Corrupt] = deque()
        self.accepted: set[int] = set()  # publication handles of the writers we listen to
        self.accepted_guid = ""
        self.refused: dict[int, str | None] = {}  # other writers: None (dropped) or why their samples are wrong


class DdsReceiver:
    """The reading end of a channel from a role in another group, or from an external role (one
    reading thread). A channel whose labels go on several topics is read lane by lane, each message
    from the topic its plan (:mod:`anodize._transport.ros_lanes`) says comes next."""

    def __init__(self, endpoints: Endpoints, codec: Codec, network: LinkNetwork, sender: str, receiver: str) -> None:
        self.codec = codec
        self.network = network
        self.endpoints = endpoints
        self.sender = sender
        self.receiver = receiver
        self.silenced = False  # our role failed and its readers are deleted: a receive now is a stop
        settings = endpoints.settings
        self.external = settings.is_external(sender)  # a ROS node: only ROS topics, no credits
        self.waitset = WaitSet(endpoints.participant)
        self.frames: InLane | None = None
        if not self.external:
            self.frames = InLane(DataReader(endpoints.participant, endpoints.topic((sender, receiver)),
                                            qos=endpoints.reader_qos), None, None, "")
        self.ros: dict[str, InLane] = {}  # ROS topic name -> its lane
        self.plan: LanePlan | None = None
        if settings.ros is not None:
            for label, topic in settings.ros.channel_topics(sender, receiver).items():
                dds_topic, kind = endpoints.ros_topic(topic)
                profile = settings.ros.qos_of(topic.name)
                self.ros[topic.name] = InLane(DataReader(endpoints.participant, dds_topic,
                                                         qos=endpoints.ros_qos(kind, False, profile)),
                                              label, kind, topic.name, profile.lossy)
            self.plan = settings.ros.plans.get((sender, receiver))
        self.lanes = [lane for lane in (self.frames, *self.ros.values()) if lane is not None]
        for lane in self.lanes:
            self.waitset.attach(ReadCondition(lane.reader, ANY_SAMPLE))
        self.state = self.plan.initial if self.plan is not None else 0
        self.credit_writer: DataWriter[Frame] | None = None
        if not self.external:
            self.credit_writer = DataWriter(endpoints.participant, endpoints.topic((sender, receiver), "/credit"),
                                            qos=endpoints.credit_qos)
            self._credit_ref = ref_of(self.credit_writer)
        self.taken = 0     # samples of the accepted writer handed on so far
        self.credited = 0  # the count last told to the sender
        self.credit_every = credit_every_for(network.capacities.get((sender, receiver)))
        self._uncredited_bytes = 0  # taken since then
        self.frame_size = 0
        self._pushed: deque[object] = deque()
        self._lost: str | None = None
        self._next_check = 0.0  # when to look again whether the accepted writer is still there
        self.rejected: dict[str, list[Any]] = {}  # foreign writer GUID -> [count, identity]

    @property
    def reader(self) -> DataReader[Any]:
        """The reader of the channel's own topic (or of its first ROS topic, from an external role)."""
        return self.lanes[0].reader

    def _lane(self) -> InLane:
        """The lane the next message comes on."""
        if self.plan is None:
            return self.lanes[0]
        topic = self.plan.lanes[self.state]
        return self.frames if topic is None and self.frames is not None else self.ros.get(topic or "", self.lanes[0])

    # ---- start barrier --------------------------------------------------------------------
    def find_writer(self) -> bool:
        """Accept the writer of the expected group on every lane, if it has matched (the start
        barrier); from an external role, some ROS node publishing each topic."""
        found = True
        for lane in self.lanes:
            matched = matched_publications(lane.reader)
            if self.external:
                found = found and bool(matched)
            elif not lane.accepted:
                channel = f"{self.sender}->{self.receiver}" + (f" ({lane.topic})" if lane.kind is not None else "")
                handle, lane.accepted_guid = find_peer(self.endpoints, self.sender, channel, matched,
                                                       lane.reader.get_matched_publication_data)
                if handle is not None:
                    lane.accepted.add(handle)
                found = found and handle is not None
        return found

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
            if self.silenced:  # a thread of our failed role still receiving: its readers are gone
                return STOP
            lane = self._lane()
            if lane.samples or self._take(lane):
                return self._hand_on(lane)
            if lane is not self.frames and self.frames is not None and self._failure_waiting():
                # The sender settled its ROS topics before it wrote the failure: a message it sent
                # there before failing is in our reader by now.
                if self._take(lane):
                    return self._hand_on(lane)
                return self._hand_on(self.frames)
            if self.network.stopping:
                return STOP
            failed = self.network.failed.get(self.sender)
            if failed is not None:
                return PeerFailure(self.sender, failed)
            lost = self._writer_lost(lane)
            if lost is not None and not self._take(lane):  # all it wrote before going is read
                self.network.note_failed(self.sender, lost)
                return PeerFailure(self.sender, lost)
            left = POLL if deadline is None else min(POLL, deadline - time.monotonic())
            if left <= 0:
                raise Empty
            self.waitset.wait(duration(seconds=left))  # releases the GIL

    def get_nowait(self) -> object:
        return self.get(timeout=0)

    def empty(self) -> bool:
        """True when nothing (no message, no failure, no stop) is waiting."""
        if self._pushed or self.silenced or self.network.stopping or self.sender in self.network.failed:
            return False
        lane = self._lane()
        if lane.samples or self._take(lane):
            return False
        return not (lane is not self.frames and self.frames is not None and self._failure_waiting())

    def _failure_waiting(self) -> bool:
        """Whether the channel's own topic holds a failure frame (when the next message is due on
        a ROS topic: messages on the own topic wait for their turn, a failure ends the channel)."""
        frames = self.frames
        assert frames is not None
        self._take(frames)
        if not frames.samples:
            return False
        last = frames.samples[-1]
        return isinstance(last, bytes) and len(last) > 12 and last[12] == FrameKind.FAILURE

    def _take(self, lane: InLane) -> bool:
        """Move what a lane's reader holds from accepted writers into its queue; False if none."""
        taken = take(lane.ref, ANY_SAMPLE, TAKE)
        if type(taken) is int:
            if self.silenced:  # deleted under us (the flag is set first): not the sender's doing
                return False
            raise AnodizeError(f"DDS take on {self.sender}->{self.receiver} failed: {DDSException(taken)}")
        for data, info in taken:
            if not info.valid_data:
                continue
            handle = instance_handle(info.publication_handle)
            if handle in lane.accepted:
                lane.samples.append(data)
            elif self._admit(lane, handle):
                reason = lane.refused.get(handle)
                lane.samples.append(data if reason is None else Corrupt(reason))
        return bool(lane.samples)

    def _admit(self, lane: InLane, handle: int) -> bool:
        """Whether a sample from a writer we have not accepted is handed on: from an external role,
        any ROS writer that claims no anodize identity is (one advertising another type hash, as a
        node built against another definition does, has its samples handed on as corrupt: the
        monitor blames the external role); any other writer's samples are dropped and reported."""
        if handle in lane.refused:
            return lane.refused[handle] is not None
        data = self._publication(lane, handle)
        claimed = userdata_of(data.qos) if data is not None else b""
        if self.external and data is not None and parse_identity(claimed) is None:
            assert lane.kind is not None
            advertised = userdata_fields(claimed).get("typehash")
            if advertised is None or advertised == lane.kind.type_hash:
                lane.accepted.add(handle)
                return True
            lane.refused[handle] = (f"the ROS 2 writer {data.key} on {lane.topic} advertises type hash "
                                    f"{advertised}, but {lane.kind.name} ({lane.kind.distro}) is "
                                    f"{lane.kind.type_hash}: it was built against another definition")
            return True
        lane.refused[handle] = None
        self._reject(lane, handle, data)
        return False

    def _publication(self, lane: InLane, handle: int) -> Any:
        matched = [h for h in matched_publications(lane.reader) if instance_handle(h) == handle]
        return lane.reader.get_matched_publication_data(matched[0]) if matched else None

    def _hand_on(self, lane: InLane) -> object:
        """The oldest sample of a lane, decoded. Credit counts what is handed on, not what is
        taken, so the sender's window covers the samples we hold too (bounded memory)."""
        data = lane.samples.popleft()
        if isinstance(data, Corrupt):
            return data
        if lane.lossy:
            return self._decode_ros(lane, data)  # a self-loop of the plan, outside the credits
        self.taken += 1
        self._uncredited_bytes += len(data)
        if self.credit_writer is not None and (self.taken - self.credited >= self.credit_every
                                               or self._uncredited_bytes >= CREDIT_BYTES):
            self.credited = self.taken
            self._uncredited_bytes = 0
            write(self._credit_ref, cdr_sample(COUNT.pack(self.taken)))  # keep-last 1: no wait
        item = self._decode(data) if lane.kind is None else self._decode_ros(lane, data)
        if self.plan is not None and type(item) is tuple:
            self.state = self.plan.after(self.state, item[0])
        return item

    def _decode_ros(self, lane: InLane, data: bytes) -> object:
        assert lane.kind is not None and lane.label is not None
        self.frame_size = len(data)
        try:
            return (lane.label, lane.kind.deserialize(data))
        except AnodizeError as error:
            return Corrupt(f"a sample on ROS topic {lane.topic} that is not a {lane.kind.name}: {error}")

    def _reject(self, lane: InLane, handle: int, data: Any) -> None:
        guid = str(data.key) if data is not None else f"handle {handle}"
        claimed = userdata_of(data.qos).decode(errors="replace") if data is not None else ""
        entry = self.rejected.setdefault(guid, [0, claimed])
        entry[0] += 1
        where = f" ({lane.topic})" if lane.kind is not None else ""
        self.endpoints.report(f"rejected samples on {self.sender}->{self.receiver}{where} from DDS writer {guid} "
                            f"(it claims {claimed or 'nothing'!r}); only {lane.accepted_guid} "
                            f"({self.endpoints.settings.where(self.sender)}) may write there")

    def _decode(self, data: bytes) -> object:
        if len(data) < 8:
            return Corrupt(f"a DDS sample of {len(data)} bytes")
        (length,) = LENGTH.unpack_from(data, 4)
        if length > MAX_FRAME + 4 or 8 + length > len(data) or length < 4:
            return Corrupt(f"a DDS sample whose sequence length {length} does not fit its {len(data)} bytes")
        (body_length,) = HEADER.unpack_from(data, 8)
        if body_length != length - 4:
            return Corrupt("a DDS sample whose frame length does not match its sequence length")
        self.frame_size = length
        try:
            kind, value = self.codec.decode_body(memoryview(data)[12:8 + length])
        except DecodeError as error:
            return Corrupt(str(error))
        if kind == FrameKind.FAILURE:
            self.network.note_failed(self.sender, value)
            return PeerFailure(self.sender, value)
        message: tuple[str, object] = value
        return message

    def _writer_lost(self, lane: InLane) -> str | None:
        """Why the writer of the lane due next is gone (deleted, lease expired), or None while it
        lives; from an external role: why no ROS node publishes there any more.

        Asks Cyclone at most every ``POLL`` seconds: a receive that finds nothing
        and waits would otherwise pay for the question every time.
        """
        now = time.monotonic()
        if self._lost is not None or now < self._next_check:
            return self._lost
        self._next_check = now + POLL
        matched = {instance_handle(h) for h in matched_publications(lane.reader)}
        where = self.endpoints.settings.where(self.sender)
        if self.external:
            if not matched:
                self._lost = f"no ROS 2 node publishes {lane.topic} any more"
        elif lane.accepted and not lane.accepted & matched:
            self._lost = f"its DDS writer went away: {where} ended, or stopped answering, or was cut off"
        elif self.frames is not None:  # our own writers assert liveliness on the channel's own topic
            status = self.frames.reader.get_liveliness_changed_status()  # type: ignore[no-untyped-call]
            if status.alive_count == 0 and status.not_alive_count > 0:
                self._lost = (f"{where} stopped answering: its DDS liveliness lease "
                              f"({self.endpoints.settings.lease:g} s) expired")
        return self._lost
