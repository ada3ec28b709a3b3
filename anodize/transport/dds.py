"""Channels between groups as DDS topics on Cyclone DDS: ``transport="dds"``.

Each group is still its own process (as with ``transport="process"``); channels
inside it stay queues, and every channel between roles of different groups is
one DDS topic, ``anodize/<run id>/<sender>/<receiver>``, with one writer (in the
sender's group) and one reader (in the receiver's). The groups may run on other
hosts: they find each other by DDS discovery on the run's domain.

- **Nothing lost, duplicated or reordered**: reliable, keep-all history on both
  ends. **Back pressure** by credits: the receiver tells the sender, on the
  channel's ``.../credit`` topic (keep-last 1), how many samples it has handed on
  to its role; the sender writes at most ``_WINDOW`` samples (and about
  ``_WINDOW_BYTES``) ahead of that, fewer than the reader's resource limit, so a
  receiver that falls behind holds bounded memory; otherwise the sender waits on
  the credit reader (in steps that look at failures and stops). The reader thus
  never rejects a sample; should it (a failure frame does not wait for credit),
  Cyclone's own reliability brings it again, and a write that finds no room is
  retried in short sleeps that release the GIL.
- **Raw bytes**: the topic type is ``anodize::Frame { sequence<octet> data; }``;
  frames of :mod:`.codec` are written as CDR built here and taken as raw CDR, so a
  900 KB array costs a copy, not the binding's element-by-element encoding.
- **Who may speak**: every writer carries its identity in its USER_DATA QoS (run
  id, group, incarnation, host, pid). A reader accepts samples only from the one
  writer of the expected group, chosen at the start barrier; samples from any
  other writer are dropped, counted and reported with the writer's GUID and
  claimed identity. This keeps other runs and stray programs out; it is not
  security: anyone on the network can claim an identity first (see the README).
- **Failures**: writers assert liveliness automatically with a lease of
  ``lease`` seconds and the participant's discovery lease is the same, so a group
  whose process dies, freezes or is cut off loses its writers and readers within
  about one lease; a blocked receiver then gets a :class:`PeerFailure`, a blocked
  sender a ``PeerFailedError``. A role that fails in a live process has a failure
  frame written after its last message, as with pipes.
"""

from __future__ import annotations

import contextlib
import os
import re
import struct
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from queue import Empty
from typing import TYPE_CHECKING, Any

from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.core import DDSException, InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ..errors import AnodizeError, PeerFailedError, RoleStopped
from ..session.channel import STOP, Corrupt, PeerFailure
from .codec import HEADER, MAX_FRAME, Codec, DecodeError, EncodeError, FrameKind
from .dds_types import Frame
from .process import PayloadError, ProcessNetwork
from .ros_lanes import LanePlan, RosSettings, RosTopic, dds_topic_of

if TYPE_CHECKING:
    from ..ros import RosType

__all__ = ["DdsSettings", "DdsNetwork", "DdsSender", "DdsReceiver", "Frame", "topic_name", "identity_of",
           "participant_config", "DOMAIN_ENV", "StartBarrierError", "ANY_SAMPLE", "cdr_sample",
           "instance_handle", "userdata_of", "READER_SAMPLES"]

DOMAIN_ENV = "ANODIZE_DDS_DOMAIN"  # overrides the system file's domain
_TIMEOUT = -10  # DDS_RETCODE_TIMEOUT: a write found no room within its blocking time
ANY_SAMPLE = SampleState.Any | ViewState.Any | InstanceState.Any
READER_SAMPLES = 256  # samples a receiver's DDS reader holds at most
# Credits: a sender has at most _WINDOW samples, and about _WINDOW_BYTES, that its receiver has
# not taken yet, so the reader never has to reject one (Cyclone then recovers only by NACK and
# retransmission, which made back pressure cost about 100 us a message) and a receiver that falls
# behind holds bounded memory (a few large frames, or many small messages); the receiver says
# how many it has taken every _CREDIT_EVERY samples or _CREDIT_BYTES bytes.
_WINDOW = 224
_WINDOW_BYTES = 16 << 20
_CREDIT_EVERY = 32
_CREDIT_BYTES = _WINDOW_BYTES // 4
_COUNT = struct.Struct("<Q")
_WRITE_BLOCK = duration(milliseconds=2)  # the longest a write holds the GIL waiting for room
_POLL = 0.05  # seconds between looks at a peer's liveliness (asking Cyclone costs tens of µs)
_TAKE = 32  # samples taken per call
_LENGTH = struct.Struct("<I")
# ROS 2 publishes plain CDR (XCDR1): its readers do not accept a writer that offers only XCDR2.
_XCDR1 = (Policy.DataRepresentation(use_cdrv0_representation=True),)


_CDR_HEADER = Frame(data=[]).serialize()[:4]  # type: ignore[arg-type]  # the encapsulation the binding itself writes


class StartBarrierError(AnodizeError):
    """Peers of a group did not appear on the DDS domain in time."""


@dataclass(frozen=True)
class DdsSettings:
    """What a group's process needs to join its run on DDS (picklable, in the group's spec).

    Attributes:
        domain: the DDS domain id.
        run_id: keeps two runs of the same system apart (part of every topic name).
        host: the host this group runs on (for messages and identities).
        group_of: role -> group, for every role of the system.
        host_of: group -> host, for every group of the system.
        lease: seconds of liveliness lease (a silent peer is failed after about this).
        wait: seconds the start barrier waits for every peer.
        ros: the channels' labels that are ROS 2 topics, and the roles ROS 2 nodes play.
    """

    domain: int
    run_id: str
    host: str
    group_of: Mapping[str, str]
    host_of: Mapping[str, str]
    lease: float = 1.0
    wait: float = 30.0
    extra_config: str = field(default="")
    ros: RosSettings | None = None

    def where(self, role: str) -> str:
        if self.is_external(role):
            return f"external role {role} (a ROS 2 node)"
        group = self.group_of[role]
        return f"group {group} on host {self.host_of.get(group, '?')}"

    def is_external(self, role: str) -> bool:
        return self.ros is not None and role in self.ros.external


def topic_name(run_id: str, sender: str, receiver: str) -> str:
    """The channel's topic: DDS names allow letters, digits, ``_`` and ``/``."""
    return "anodize/" + "/".join(_safe(part) for part in (run_id, sender, receiver))


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]", lambda m: f"_{ord(m.group()):x}_", text)


def identity_of(run_id: str, group: str, incarnation: int, host: str) -> bytes:
    """What a writer says it is (its USER_DATA)."""
    return f"anodize1;{run_id};{group};{incarnation};{host};{os.getpid()}".encode()


def ros_userdata(type_hash: str, identity: bytes) -> bytes:
    """The USER_DATA of an endpoint on a ROS topic: ``key=value;`` pairs, as ROS 2 reads them
    (``typehash=RIHS01_...;``, Iron and later), and anodize's identity as one more key."""
    return f"typehash={type_hash};anodize={identity.decode().replace(';', ',')};".encode()


def userdata_fields(data: bytes | None) -> dict[str, str]:
    """The ``key=value;`` pairs of a ROS 2 endpoint's USER_DATA (empty if it has none)."""
    try:
        text = (data or b"").decode()
    except UnicodeDecodeError:
        return {}
    return dict(part.split("=", 1) for part in text.split(";") if "=" in part)


def _parse_identity(data: bytes | None) -> tuple[str, str, int, str, int] | None:
    try:
        text = (data or b"").decode()
        if not text.startswith("anodize1;"):  # on a ROS topic, one key among ROS 2's
            text = userdata_fields(data).get("anodize", "").replace(",", ";")
        tag, run_id, group, incarnation, host, pid = text.split(";")
        return (run_id, group, int(incarnation), host, int(pid)) if tag == "anodize1" else None
    except (UnicodeDecodeError, ValueError):
        return None


def participant_config(lease: float) -> str:
    """Cyclone configuration for a group: a discovery lease of ``lease`` seconds, so a vanished
    participant (process killed, host cut off) is dropped, and its endpoints unmatched, that fast."""
    return (f"<CycloneDDS><Domain id=\"any\"><Discovery><LeaseDuration>{lease:g}s</LeaseDuration>"
            "</Discovery></Domain></CycloneDDS>")


class _Endpoints:
    """A group's participant, and the QoS of its channels."""

    def __init__(self, settings: DdsSettings, group: str, incarnation: int) -> None:
        self.settings = settings
        # Ours last: Cyclone merges comma-separated configurations, later ones winning.
        previous = os.environ.get("CYCLONEDDS_URI", "")
        os.environ["CYCLONEDDS_URI"] = ",".join(p for p in (previous, participant_config(settings.lease)) if p)
        self.participant = DomainParticipant(settings.domain)
        lease = duration(seconds=settings.lease)
        self.identity = identity_of(settings.run_id, group, incarnation, settings.host)
        self.writer_qos = Qos(Policy.Reliability.Reliable(_WRITE_BLOCK), Policy.History.KeepAll,
                              Policy.Liveliness.Automatic(lease), Policy.Userdata(self.identity))
        self.reader_qos = Qos(Policy.Reliability.Reliable(_WRITE_BLOCK), Policy.History.KeepAll,
                              Policy.ResourceLimits(max_samples=READER_SAMPLES),
                              Policy.Liveliness.Automatic(lease), Policy.Userdata(self.identity))
        self.credit_qos = Qos(Policy.Reliability.Reliable(_WRITE_BLOCK), Policy.History.KeepLast(1),
                              Policy.Liveliness.Automatic(lease), Policy.Userdata(self.identity))
        self.topics: dict[str, Topic[Any]] = {}

    def topic(self, pair: tuple[str, str], suffix: str = "") -> Topic[Frame]:
        name = topic_name(self.settings.run_id, *pair) + suffix
        if name not in self.topics:
            self.topics[name] = Topic(self.participant, name, Frame)
        return self.topics[name]

    def ros_topic(self, topic: RosTopic) -> tuple[Topic[Any], RosType]:
        """The DDS topic of a ROS topic (``rt/...``, the ROS type's DDS name and layout)."""
        from ..ros import ros_type  # only a run with ROS topics needs the message definitions

        assert self.settings.ros is not None
        kind = ros_type(topic.type_name, self.settings.ros.distro or None)
        name = dds_topic_of(topic.name)
        if name not in self.topics:
            self.topics[name] = Topic(self.participant, name, kind.idl_class())
        return self.topics[name], kind

    def ros_qos(self, kind: RosType, writer: bool) -> Qos:
        """QoS that ROS 2's default and sensor-data profiles match: reliable, volatile. Writers
        assert liveliness as on anodize's own topics; readers ask for none, since a ROS 2
        writer offers an infinite lease and a reader asking for less would not match it."""
        userdata = Policy.Userdata(ros_userdata(kind.type_hash, self.identity))
        if writer:
            return Qos(Policy.Reliability.Reliable(_WRITE_BLOCK), Policy.History.KeepAll, Policy.Durability.Volatile,
                       Policy.Liveliness.Automatic(duration(seconds=self.settings.lease)), userdata, *_XCDR1)
        return Qos(Policy.Reliability.Reliable(_WRITE_BLOCK), Policy.History.KeepAll, Policy.Durability.Volatile,
                   Policy.ResourceLimits(max_samples=READER_SAMPLES), userdata, *_XCDR1)


class _OutLane:
    """One topic a sender writes: the channel's own (codec frames) or a ROS topic (one label's CDR)."""

    def __init__(self, writer: DataWriter[Any], kind: RosType | None, topic: str) -> None:
        self.writer = writer
        self.ref = writer._ref
        self.kind = kind  # None: the channel's own topic
        self.topic = topic
        self.accepted: int | None = None  # the subscription handle of the receiver's reader (None: any, external)


class DdsSender:
    """The writing end of a channel to a role in another group, or to an external role (over DDS)."""

    def __init__(self, endpoints: _Endpoints, codec: Codec, network: DdsNetwork, sender: str, receiver: str) -> None:
        self.codec = codec
        self.network = network
        self.sender = sender
        self.receiver = receiver
        settings = network.settings
        self.external = settings.is_external(receiver)  # a ROS node: only ROS topics, no credits
        self._lock = threading.Lock()  # a failure frame must not interleave with a message
        self._next_check = 0.0  # when to look again whether the receiver's readers are still there
        self.frames: _OutLane | None = None
        if not self.external:
            self.frames = _OutLane(DataWriter(endpoints.participant, endpoints.topic((sender, receiver)),
                                              qos=endpoints.writer_qos), None, "")
        self.ros: dict[str, _OutLane] = {}  # label -> its ROS topic's writer
        if settings.ros is not None:
            for label, topic in settings.ros.channel_topics(sender, receiver).items():
                dds_topic, kind = endpoints.ros_topic(topic)
                self.ros[label] = _OutLane(DataWriter(endpoints.participant, dds_topic,
                                                      qos=endpoints.ros_qos(kind, writer=True)), kind, topic.name)
        self.lanes = [lane for lane in (self.frames, *self.ros.values()) if lane is not None]
        self.credits: DataReader[Frame] | None = None
        self.credit_writer: int | None = None  # the publication handle of the receiver's credit writer
        if not self.external:
            self.credits = DataReader(endpoints.participant, endpoints.topic((sender, receiver), "/credit"),
                                      qos=endpoints.credit_qos)
            self._credits_ref = self.credits._ref
            self._credit_wait = WaitSet(endpoints.participant)
            self._credit_wait.attach(ReadCondition(self.credits, ANY_SAMPLE))
        self.written = 0  # messages written
        self.taken = 0    # of those, how many the receiver says it has taken
        self.window = min(_WINDOW, network.capacities.get((sender, receiver), _WINDOW))  # a capacity narrows it
        self._credit_look = _CREDIT_EVERY  # when put() next reads the credits that came
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
            with self._lock:
                if self.credits is not None and self.written >= self._credit_look:
                    # Read what credits came once every so many writes (a take costs microseconds),
                    # so qsize(), the report's backlog, stays true to within a credit or two.
                    self._credit_look = self.written + _CREDIT_EVERY
                    self._take_credits()
                if self.credits is not None and (self.written - self.taken >= self.window
                                                 or self._in_flight_bytes >= _WINDOW_BYTES):
                    self._await_credit()
                self._write(lane or self.frames, sample)  # type: ignore[arg-type]
                if self.credits is not None:
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
                lane.writer.wait_for_acks(duration(seconds=seconds))

    def _write(self, lane: _OutLane, sample: bytes, give_up: float | None = None) -> None:
        pause = 0.0002
        while True:
            # A reader gone since the last look takes what is written meanwhile nowhere;
            # its group is gone too, so this only bounds how soon the sender hears of it.
            now = time.monotonic()
            if now >= self._next_check:
                self._next_check = now + _POLL
                self._check_readers()
            ret = ddspy_write(lane.ref, sample)
            if ret == 0:
                return
            if ret != _TIMEOUT:
                raise AnodizeError(f"DDS write on {self.sender}->{self.receiver} failed: {DDSException(ret)}")
            self._next_check = 0.0  # held back: is the receiver still there?
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
            matched = lane.writer.get_matched_subscriptions()
            if lane.accepted is None:
                if self.external and not matched:
                    raise self._peer_gone(f"no ROS 2 node subscribes {lane.topic} any more")
            elif lane.accepted not in {instance_handle(h) for h in matched}:
                raise self._peer_gone()

    def _await_credit(self) -> None:
        """Until the receiver has taken enough for another sample to fit its window.

        Raises:
            RoleStopped: the run is stopping.
            PeerFailedError: the receiver failed, or its reader is gone.
        """
        while True:
            self._take_credits()
            if self.written - self.taken < self.window and self._in_flight_bytes < _WINDOW_BYTES:
                return
            if self.network.stopping:
                raise RoleStopped(f"interrupted sending to {self.receiver}")
            if self.receiver in self.network.failed:
                raise self._peer_gone()
            now = time.monotonic()
            if now >= self._next_check:
                self._next_check = now + _POLL
                self._check_readers()
            self._credit_wait.wait(duration(seconds=_POLL))  # releases the GIL

    def _take_credits(self) -> None:
        taken = ddspy_take(self._credits_ref, ANY_SAMPLE, 8)
        if type(taken) is int:
            raise AnodizeError(f"DDS take of credits on {self.sender}->{self.receiver} failed: "
                               f"{DDSException(taken)}")
        for data, info in taken:
            # Only the receiver's own credit writer counts: forged credits could overrun its reader.
            if info.valid_data and instance_handle(info.publication_handle) == self.credit_writer and len(data) >= 16:
                self.taken = max(self.taken, min(_COUNT.unpack_from(data, 8)[0], self.written))
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
            matched = lane.writer.get_matched_subscriptions()
            if self.external:
                found = found and bool(matched)
            elif lane.accepted is None:
                lane.accepted = _find_peer(self.network, self.receiver, channel, matched,
                                           lane.writer.get_matched_subscription_data)[0]
                found = found and lane.accepted is not None
        if self.credits is not None and self.credit_writer is None:
            self.credit_writer = _find_peer(self.network, self.receiver, f"{self.sender}->{self.receiver} (credits)",
                                            self.credits.get_matched_publications(),
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

    def buffer(self, shape: tuple[int, ...], dtype: object) -> object:
        """A numpy array to fill and send (DDS copies it into the sample anyway)."""
        import numpy as np

        return np.empty(shape, dtype)  # type: ignore[call-overload]

    def get(self, *, timeout: float | None = None) -> object:
        """Never used: this is the writing end.

        Raises:
            AnodizeError: always.
        """
        raise AnodizeError(f"the channel {self.sender}->{self.receiver} is read in {self.receiver}'s group")

    def get_nowait(self) -> object:
        """Never used: as :meth:`get`."""
        return self.get()

    def empty(self) -> bool:
        """True: nothing arrives at the writing end."""
        return True

    def _peer_gone(self, why: str = "") -> BaseException:
        cause = self.network.failed.get(self.receiver)
        if cause is None:
            cause = why or (f"its reader went away ({self.network.settings.where(self.receiver)} ended, "
                            "or stopped answering, or was cut off)")
        return PeerFailedError(self.sender, self.receiver, cause)


class _InLane:
    """One topic a receiver reads: the channel's own (codec frames) or a ROS topic (one label)."""

    def __init__(self, reader: DataReader[Any], label: str | None, kind: RosType | None, topic: str) -> None:
        self.reader = reader
        self.ref = reader._ref
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
    from the topic its plan (:mod:`.ros_lanes`) says comes next."""

    def __init__(self, endpoints: _Endpoints, codec: Codec, network: DdsNetwork, sender: str, receiver: str) -> None:
        self.codec = codec
        self.network = network
        self.sender = sender
        self.receiver = receiver
        settings = network.settings
        self.external = settings.is_external(sender)  # a ROS node: only ROS topics, no credits
        self.waitset = WaitSet(endpoints.participant)
        self.frames: _InLane | None = None
        if not self.external:
            self.frames = _InLane(DataReader(endpoints.participant, endpoints.topic((sender, receiver)),
                                             qos=endpoints.reader_qos), None, None, "")
        self.ros: dict[str, _InLane] = {}  # ROS topic name -> its lane
        self.plan: LanePlan | None = None
        if settings.ros is not None:
            for label, topic in settings.ros.channel_topics(sender, receiver).items():
                dds_topic, kind = endpoints.ros_topic(topic)
                self.ros[topic.name] = _InLane(DataReader(endpoints.participant, dds_topic,
                                                          qos=endpoints.ros_qos(kind, writer=False)),
                                               label, kind, topic.name)
            self.plan = settings.ros.plans.get((sender, receiver))
        self.lanes = [lane for lane in (self.frames, *self.ros.values()) if lane is not None]
        for lane in self.lanes:
            self.waitset.attach(ReadCondition(lane.reader, ANY_SAMPLE))
        self.state = self.plan.initial if self.plan is not None else 0
        self.credit_writer: DataWriter[Frame] | None = None
        if not self.external:
            self.credit_writer = DataWriter(endpoints.participant, endpoints.topic((sender, receiver), "/credit"),
                                            qos=endpoints.credit_qos)
        self.taken = 0     # samples of the accepted writer handed on so far
        self.credited = 0  # the count last told to the sender
        # Credit at least twice per window: a capacity narrows the sender's window below _CREDIT_EVERY.
        capacity = network.capacities.get((sender, receiver))
        self.credit_every = _CREDIT_EVERY if capacity is None else max(1, min(_CREDIT_EVERY, capacity // 2))
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

    def _lane(self) -> _InLane:
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
            matched = lane.reader.get_matched_publications()
            if self.external:
                found = found and bool(matched)
            elif not lane.accepted:
                channel = f"{self.sender}->{self.receiver}" + (f" ({lane.topic})" if lane.kind is not None else "")
                handle, lane.accepted_guid = _find_peer(self.network, self.sender, channel, matched,
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
            left = _POLL if deadline is None else min(_POLL, deadline - time.monotonic())
            if left <= 0:
                raise Empty
            self.waitset.wait(duration(seconds=left))  # releases the GIL

    def get_nowait(self) -> object:
        return self.get(timeout=0)

    def empty(self) -> bool:
        """True when nothing (no message, no failure, no stop) is waiting."""
        if self._pushed or self.network.stopping or self.sender in self.network.failed:
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

    def _take(self, lane: _InLane) -> bool:
        """Move what a lane's reader holds from accepted writers into its queue; False if none."""
        taken = ddspy_take(lane.ref, ANY_SAMPLE, _TAKE)
        if type(taken) is int:
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

    def _admit(self, lane: _InLane, handle: int) -> bool:
        """Whether a sample from a writer we have not accepted is handed on: from an external role,
        any ROS writer that claims no anodize identity is (one advertising another type hash, as a
        node built against another definition does, has its samples handed on as corrupt: the
        monitor blames the external role); any other writer's samples are dropped and reported."""
        if handle in lane.refused:
            return lane.refused[handle] is not None
        data = self._publication(lane, handle)
        claimed = userdata_of(data.qos) if data is not None else b""
        if self.external and data is not None and _parse_identity(claimed) is None:
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

    def _publication(self, lane: _InLane, handle: int) -> Any:
        matched = [h for h in lane.reader.get_matched_publications() if instance_handle(h) == handle]
        return lane.reader.get_matched_publication_data(matched[0]) if matched else None

    def _hand_on(self, lane: _InLane) -> object:
        """The oldest sample of a lane, decoded. Credit counts what is handed on, not what is
        taken, so the sender's window covers the samples we hold too (bounded memory)."""
        data = lane.samples.popleft()
        if isinstance(data, Corrupt):
            return data
        self.taken += 1
        self._uncredited_bytes += len(data)
        if self.credit_writer is not None and (self.taken - self.credited >= self.credit_every
                                               or self._uncredited_bytes >= _CREDIT_BYTES):
            self.credited = self.taken
            self._uncredited_bytes = 0
            ddspy_write(self.credit_writer._ref, cdr_sample(_COUNT.pack(self.taken)))  # keep-last 1: no wait
        item = self._decode(data) if lane.kind is None else self._decode_ros(lane, data)
        if self.plan is not None and type(item) is tuple:
            self.state = self.plan.after(self.state, item[0])
        return item

    def _decode_ros(self, lane: _InLane, data: bytes) -> object:
        assert lane.kind is not None and lane.label is not None
        self.frame_size = len(data)
        try:
            return (lane.label, lane.kind.deserialize(data))
        except AnodizeError as error:
            return Corrupt(f"a sample on ROS topic {lane.topic} that is not a {lane.kind.name}: {error}")

    def _reject(self, lane: _InLane, handle: int, data: Any) -> None:
        guid = str(data.key) if data is not None else f"handle {handle}"
        claimed = userdata_of(data.qos).decode(errors="replace") if data is not None else ""
        entry = self.rejected.setdefault(guid, [0, claimed])
        entry[0] += 1
        where = f" ({lane.topic})" if lane.kind is not None else ""
        self.network.report(f"rejected samples on {self.sender}->{self.receiver}{where} from DDS writer {guid} "
                            f"(it claims {claimed or 'nothing'!r}); only {lane.accepted_guid} "
                            f"({self.network.settings.where(self.sender)}) may write there")

    def _decode(self, data: bytes) -> object:
        if len(data) < 8:
            return Corrupt(f"a DDS sample of {len(data)} bytes")
        (length,) = _LENGTH.unpack_from(data, 4)
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

    def _writer_lost(self, lane: _InLane) -> str | None:
        """Why the writer of the lane due next is gone (deleted, lease expired), or None while it
        lives; from an external role: why no ROS node publishes there any more.

        Asks Cyclone at most every ``_POLL`` seconds: a receive that finds nothing
        and waits would otherwise pay for the question every time.
        """
        now = time.monotonic()
        if self._lost is not None or now < self._next_check:
            return self._lost
        self._next_check = now + _POLL
        matched = {instance_handle(h) for h in lane.reader.get_matched_publications()}
        where = self.network.settings.where(self.sender)
        if self.external:
            if not matched:
                self._lost = f"no ROS 2 node publishes {lane.topic} any more"
        elif lane.accepted and not lane.accepted & matched:
            self._lost = f"its DDS writer went away: {where} ended, or stopped answering, or was cut off"
        elif self.frames is not None:  # our own writers assert liveliness on the channel's own topic
            status = self.frames.reader.get_liveliness_changed_status()  # type: ignore[no-untyped-call]
            if status.alive_count == 0 and status.not_alive_count > 0:
                self._lost = (f"{where} stopped answering: its DDS liveliness lease "
                              f"({self.network.settings.lease:g} s) expired")
        return self._lost


class DdsNetwork(ProcessNetwork):
    """The channels of one group's process with ``transport="dds"``.

    Args:
        settings: the run's DDS settings.
        group, incarnation: this group.
        local_roles, channels, dead, codec_for, doorbell_roles: as for
            :class:`~anodize.transport.process.ProcessNetwork`.
        report: called with a line for the group's report (e.g. a rejected writer).
    """

    def __init__(self, settings: DdsSettings, group: str, incarnation: int, local_roles: Iterable[str],
                 channels: Iterable[tuple[str, str]], dead: dict[str, str],
                 codec_for: Callable[[tuple[str, str]], Codec], doorbell_roles: Iterable[str] = (),
                 report: Callable[[str], None] = lambda line: None,
                 capacities: Mapping[tuple[str, str], int] | None = None) -> None:
        self.settings = settings
        self.report = report
        self.incarnation = incarnation
        self.endpoints = _Endpoints(settings, group, incarnation)
        local = frozenset(local_roles)
        channels = tuple(channels)
        remote = {pair: self.endpoints for pair in channels
                  if (pair[0] in local) != (pair[1] in local) and not ({pair[0], pair[1]} & set(dead))}
        self.senders: list[DdsSender] = []
        self.receivers: list[DdsReceiver] = []
        super().__init__(local, channels, remote, dead, codec_for, doorbell_roles, capacities)

    def _writer(self, link: Any, codec: Codec, sender: str, receiver: str) -> DdsSender:
        channel = DdsSender(link, codec, self, sender, receiver)
        self.senders.append(channel)
        return channel

    def _reader(self, link: Any, codec: Codec, sender: str, receiver: str) -> DdsReceiver:
        channel = DdsReceiver(link, codec, self, sender, receiver)
        self.receivers.append(channel)
        return channel

    def _silence(self, pair: tuple[str, str]) -> None:
        # Our receiver failed: delete its reader, so its writer sees it unmatched and stops.
        for receiver in self.receivers:
            if (receiver.sender, receiver.receiver) == pair:
                for lane in receiver.lanes:
                    with contextlib.suppress(DDSException):
                        lane.reader.__del__()

    def wait_for_peers(self) -> None:
        """The start barrier: every channel's other end has appeared, or the wait is over.

        Raises:
            StartBarrierError: naming the groups and hosts that never appeared.
        """
        deadline = time.monotonic() + self.settings.wait
        while True:
            missing = self._missing()
            if not missing:
                return
            if time.monotonic() > deadline:
                settings = self.settings
                raise StartBarrierError(
                    f"after {settings.wait:g} s on DDS domain {settings.domain} (run {settings.run_id}), "
                    f"no sign of {'; '.join(missing)}: is it started (anodize run ... --host), with the same "
                    f"run id, domain and network?")
            time.sleep(0.02)

    def _missing(self) -> list[str]:
        missing: dict[str, list[str]] = {}
        for sender in self.senders:
            if not sender.find_reader():
                missing.setdefault(self.settings.where(sender.receiver), []).append(
                    f"{sender.sender}->{sender.receiver}" + _on_topics(sender.ros))
        for receiver in self.receivers:
            if not receiver.find_writer():
                missing.setdefault(self.settings.where(receiver.sender), []).append(
                    f"{receiver.sender}->{receiver.receiver}" + _on_topics(receiver.ros.values()))
        return [f"{where} (for {', '.join(pairs)})" for where, pairs in sorted(missing.items())]

    def close(self, linger: float = 2.0) -> None:
        """Wait (bounded) until every sample written has been acknowledged, before the process ends."""
        for sender in self.senders:
            for lane in sender.lanes:
                with contextlib.suppress(DDSException):
                    lane.writer.wait_for_acks(duration(seconds=linger))


def _on_topics(lanes: Iterable[_OutLane | _InLane] | Mapping[str, _OutLane]) -> str:
    topics = [lane.topic for lane in (lanes.values() if isinstance(lanes, Mapping) else lanes)]
    return f" on ROS topic{'s' if len(topics) > 1 else ''} {', '.join(topics)}" if topics else ""


def _find_peer(network: DdsNetwork, role: str, channel: str, handles: Iterable[int],
               data_of: Callable[[int], Any]) -> tuple[int | None, str]:
    """The handle and GUID of the one matched endpoint that says it is ``role``'s group of
    our run and incarnation, or (None, "") while there is none.

    Raises:
        StartBarrierError: several claim it (never guess which one is genuine).
    """
    settings = network.settings
    expected = settings.group_of[role]
    claims = []
    for handle in handles:
        data = data_of(handle)
        identity = _parse_identity(userdata_of(data.qos)) if data is not None else None
        # A restart starts its batch of groups as one incarnation: an endpoint of an older
        # one is the session we left, not a peer of this one.
        if identity is not None and identity[:3] == (settings.run_id, expected, network.incarnation):
            claims.append((instance_handle(handle), str(data.key), identity))
    if len(claims) > 1:
        raise StartBarrierError(
            f"{len(claims)} DDS endpoints on {channel} claim to be {settings.where(role)}: "
            + ", ".join(f"{guid} (pid {identity[4]} on {identity[3]})" for _, guid, identity in claims)
            + "; is the same run started twice, or is someone forging it?")
    if claims:
        handle, guid, _ = claims[0]
        return handle, guid
    return None, ""


def cdr_sample(frame: bytes) -> bytes:
    """A codec frame (4-byte length, body) as the CDR of an ``anodize::Frame`` sample."""
    sample = _CDR_HEADER + _LENGTH.pack(len(frame)) + frame
    return sample + b"\0" * (-len(sample) % 4)


def ros_sample(cdr: bytes) -> bytes:
    """Serialized ROS data padded to a multiple of 4 bytes, the padding counted in the low bits of the
    encapsulation options (as XTypes says and Cyclone's own serializer does)."""
    pad = -len(cdr) % 4
    if not pad:
        return cdr
    return cdr[:3] + bytes((cdr[3] | pad,)) + cdr[4:] + b"\0" * pad


def instance_handle(handle: int) -> int:
    """An instance handle as one number: the binding gives the same 64 bits signed in one
    place and unsigned in another."""
    return handle & 0xFFFF_FFFF_FFFF_FFFF


def userdata_of(qos: Qos | None) -> bytes:
    if qos is None:
        return b""
    try:
        policy = qos[Policy.Userdata]
    except (KeyError, TypeError):
        return b""
    data = getattr(policy, "data", b"")
    return data if isinstance(data, bytes) else b""
