"""A run's ROS 2 topics on a Zenoh session, as rmw_zenoh publishes them.

On ``transport = "zenoh"`` each group process that sends on a mapped channel
(``[ros.topics]``) is one ROS 2 node on rmw_zenoh's graph: it declares the node's
liveliness token, a publisher token and a Zenoh publisher per topic it sends, and puts
each message on the topic's key expression with rmw_zenoh's attachment (sequence
number from 1, timestamp, the publisher's GID), the payload the CDR a ROS 2 node
publishes (:meth:`anodize._ros.RosType.serialize`, the DDS path's bytes). A ROS 2 node
on rmw_zenoh, on the same Zenoh network and ``ROS_DOMAIN_ID``, then lists the topic and
receives its messages. The format is :mod:`anodize._ros.rmw_zenoh`'s.

A role that a ROS 2 node plays (``[ros] external``) sends on topics anodize subscribes
to here (:meth:`RosTopicsNode.inbox`): a subscription token, and a Zenoh subscriber on
the topic under *any* type hash, so that a node built against another definition of the
message is seen and refused by name instead of silently never matching. What it takes
(attachment, key) is hostile and checked; nothing here raises for it.

Zenoh is reached only through :mod:`.binding`.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Collection
from dataclasses import dataclass

from ..._ros import RosType, ros_type
from ..._ros.rmw_zenoh import (
    Attachment,
    Entity,
    RmwQos,
    RmwZenohFormatError,
    TopicInfo,
    encode_attachment,
    entity_gid,
    entity_key,
    parse_attachment,
    topic_key,
)
from ..qos_profiles import QosProfile
from ..ros_lanes import RosSettings, RosTopic
from .binding import Sample, Session, attachment_of, key_of, payload_of, publisher, subscribe, token, undeclare

__all__ = ["RosTopicsNode", "RosPublisher", "RosInbox", "RosSample", "node_name_of"]

INBOX_CAPACITY = 4096  # samples of a keep-all topic an external node may run ahead of the protocol
INBOX_BYTES = 256 * 1024 * 1024  # and bytes: some hundred camera frames
ENCLAVE = "/"  # rcl's enclave when SROS is off


def node_name_of(group: str) -> str:
    """A ROS node name for a group: letters, digits and ``_``, not starting with a digit."""
    name = "".join(c if c.isascii() and (c.isalnum() or c == "_") else "_" for c in group) or "anodize"
    return name if not name[0].isdigit() else "_" + name


def _rmw_qos(profile: QosProfile) -> RmwQos:
    return RmwQos.of(profile.reliability, profile.history, profile.depth, profile.durability)


@dataclass(frozen=True)
class RosSample:
    """One sample an external ROS node put on a topic anodize subscribes to.

    Attributes:
        topic: the ROS topic.
        payload: its bytes (CDR, if the node is what it claims).
        attachment: rmw_zenoh's attachment, or None when it had none or it did not parse.
        problem: why the sample cannot be taken as the topic's message (another type hash, a
            malformed attachment), or None.
    """

    topic: str
    payload: bytes
    attachment: Attachment | None
    problem: str | None = None


class RosPublisher:
    """One topic's publisher: its liveliness token, its Zenoh publisher, its sequence numbers."""

    def __init__(self, session: Session, entity: Entity, key: str, kind: RosType, qos: QosProfile,
                 clock: Callable[[], int] = time.time_ns) -> None:
        self.entity = entity
        self.kind = kind
        self.key = key
        self.token_key = entity_key(entity)
        self.gid = entity_gid(self.token_key)
        reliable = qos.reliability == "reliable"
        # As rmw_publisher_data.cpp: drop under congestion unless reliable and keep-all, then block.
        block = reliable and qos.history == "keep_all"
        # Transient local: rmw_zenoh's advanced publisher with a cache of ``depth`` samples.
        cache = qos.depth if qos.durability == "transient_local" else 0
        self._publisher = publisher(session, key, reliable=reliable, block=block, cache=cache)
        self._token = token(session, self.token_key)
        self._clock = clock
        self._lock = threading.Lock()
        self.sequence = 0  # the last number put; rmw_zenoh's first sample is 1

    def put(self, payload: bytes | bytearray | memoryview) -> None:
        """Publish one message's CDR with the next sequence number and now as its timestamp."""
        with self._lock:  # numbers in the order the samples go out
            self.sequence += 1
            attachment = encode_attachment(Attachment(self.sequence, self._clock(), self.gid))
            self._publisher.put(bytes(payload), attachment=attachment)

    def matched(self) -> bool:
        """Whether some subscriber on the Zenoh network takes this topic's samples now."""
        status: object = self._publisher.matching_status  # a MatchingStatus (the binding's stub says bool)
        return bool(getattr(status, "matching", status))

    def close(self) -> None:
        """Undeclare the token (the graph sees the publisher go) and the publisher."""
        undeclare(self._token)
        undeclare(self._publisher)


class RosInbox:
    """A subscription to a topic an external ROS node publishes: bounded, checked, never raising for
    what comes, never holding up Zenoh's thread.

    A keep-last topic keeps its newest ``keep_last`` samples, as a keep-last reader does (the
    oldest are dropped and counted). A keep-all topic's samples may not be dropped: past
    ``capacity`` samples or :data:`INBOX_BYTES` bytes not yet taken, the inbox takes no more
    and ends with a sample whose ``problem`` says the node ran that far ahead of the protocol
    (the receiver hands it on as corrupt, blaming the node's role).
    """

    def __init__(self, session: Session, entity: Entity, topic: RosTopic, kind: RosType, domain: int,
                 capacity: int = INBOX_CAPACITY, keep_last: int = 0) -> None:
        dds_type, type_hash = kind.dds_name, kind.type_hash
        self.keep_last = keep_last  # a keep-last topic's depth (0: keep all)
        self.capacity = keep_last or capacity
        self.dropped = 0  # samples dropped: overwritten (keep last), or past an overrun (keep all)
        self.entity = entity
        self.kind = kind
        self.topic = topic
        self.key = topic_key(domain, topic.name, dds_type, type_hash)
        self._hash = type_hash
        self.token_key = entity_key(entity)
        self._samples: deque[RosSample] = deque()
        self._bytes = 0
        self._overrun = False
        self._arrived = threading.Condition()
        # Any hash: a node with another definition of the message is seen, and refused by name.
        wildcard = topic_key(domain, topic.name, dds_type, "*")
        self._subscriber = subscribe(session, wildcard, self._on_sample)
        self._token = token(session, self.token_key)

    def _on_sample(self, sample: Sample) -> None:
        """On Zenoh's thread: check the sample and keep it (or drop it, as the class says)."""
        taken = self._sample(sample)
        with self._arrived:
            if self._overrun:
                self.dropped += 1
                return
            full = len(self._samples) >= self.capacity or self._bytes + len(taken.payload) > INBOX_BYTES
            if full and self.keep_last and self._samples:
                self._bytes -= len(self._samples.popleft().payload)
                self.dropped += 1
            elif full:
                self._overrun = True
                self.dropped += 1
                taken = RosSample(self.topic.name, b"", None,
                                  f"the node ran {len(self._samples)} messages ({self._bytes} bytes) ahead of the "
                                  f"protocol on {self.topic.name}, more than anodize holds for a topic whose "
                                  "messages may not be lost (keep all)")
            self._samples.append(taken)
            self._bytes += len(taken.payload)
            self._arrived.notify_all()

    def _sample(self, sample: Sample) -> RosSample:
        payload = payload_of(sample)
        found = key_of(sample).rsplit("/", 1)[-1]
        problem = None
        if found != self._hash:
            problem = (f"the publisher's type hash is {found[:80]}, {self.topic.type_name} here is {self._hash} "
                       "(a node built against another definition of the message)")
        attachment = None
        raw = attachment_of(sample)
        if not raw:
            problem = problem or "the sample has no rmw_zenoh attachment"
        else:
            try:
                attachment = parse_attachment(raw)
            except RmwZenohFormatError as error:
                problem = problem or str(error)
        return RosSample(self.topic.name, payload, attachment, problem)

    def take(self, timeout: float) -> RosSample | None:
        """The next sample, waiting at most ``timeout`` seconds (None: none came)."""
        deadline = time.monotonic() + max(0.0, timeout)
        with self._arrived:
            while not self._samples:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._arrived.wait(left)
            taken = self._samples.popleft()
            self._bytes -= len(taken.payload)
            return taken

    def qsize(self) -> int:
        """Samples taken from the network and not handed on yet."""
        return len(self._samples)

    def empty(self) -> bool:
        return not self._samples

    def close(self) -> None:
        """Undeclare the token and the subscriber."""
        undeclare(self._token)
        undeclare(self._subscriber)


class RosTopicsNode:
    """The ROS 2 node one group process is on rmw_zenoh's graph.

    Args:
        session: an open ``zenoh.Session``.
        settings: the run's ROS side (:class:`~anodize._transport.ros_lanes.RosSettings`).
        group: the group's name (the node's name, made a ROS name).
        roles: the roles this process runs: it publishes the topics they send to roles
            elsewhere, and subscribes the topics they receive from an external role.
        namespace: the node's ROS namespace (``/`` when none).
        clock: ns since the epoch, for the attachments' timestamps.
    """

    def __init__(self, session: Session, settings: RosSettings, group: str, roles: Collection[str],
                 namespace: str = "/", clock: Callable[[], int] = time.time_ns) -> None:
        self.settings = settings
        self.domain = settings.domain
        self.publishers: dict[tuple[str, str, str], RosPublisher] = {}
        self.inboxes: dict[tuple[str, str, str], RosInbox] = {}
        zid = str(session.zid())
        self.node = Entity(self.domain, zid, "0", "0", "NN", ENCLAVE, namespace or "/", node_name_of(group))
        self._node_token = token(session, entity_key(self.node))
        here = set(roles)
        number = 0
        try:
            for (sender, receiver, label), topic in sorted(settings.topics.items()):
                kind = ros_type(topic.type_name, settings.distro or None)
                qos = settings.qos_of(topic.name)
                info = TopicInfo(topic.name, kind.dds_name, kind.type_hash, _rmw_qos(qos))
                if sender in here and receiver not in here:  # within a group a channel is no topic
                    number += 1
                    entity = Entity(self.domain, zid, "0", str(number), "MP", ENCLAVE, self.node.namespace,
                                    self.node.node, info)
                    self.publishers[(sender, receiver, label)] = RosPublisher(
                        session, entity, topic_key(self.domain, topic.name, kind.dds_name, kind.type_hash), kind,
                        qos, clock)
                elif receiver in here and sender in settings.external:
                    number += 1
                    entity = Entity(self.domain, zid, "0", str(number), "MS", ENCLAVE, self.node.namespace,
                                    self.node.node, info)
                    depth = qos.depth if qos.history == "keep_last" else 0
                    self.inboxes[(sender, receiver, label)] = RosInbox(session, entity, topic, kind, self.domain,
                                                                       keep_last=depth)
        except BaseException:
            self.close()
            raise

    def lanes(self, sender: str, receiver: str) -> dict[str, RosPublisher]:
        """The publishers of a channel's mapped labels here: label -> its topic's publisher."""
        return {label: lane for (s, r, label), lane in self.publishers.items() if (s, r) == (sender, receiver)}

    def publish(self, sender: str, receiver: str, label: str, payload: bytes | bytearray | memoryview) -> bool:
        """Put a message's CDR on its topic, if ``label`` of ``sender->receiver`` is mapped here (False: it is not)."""
        lane = self.publishers.get((sender, receiver, label))
        if lane is None:
            return False
        lane.put(payload)
        return True

    def inboxes_of(self, sender: str, receiver: str) -> dict[str, RosInbox]:
        """The subscriptions of a channel from an external role: label -> its topic's inbox."""
        return {label: inbox for (s, r, label), inbox in self.inboxes.items() if (s, r) == (sender, receiver)}

    def inbox(self, sender: str, receiver: str, label: str) -> RosInbox | None:
        """The subscription to a topic an external role sends on, received here (None: not one)."""
        return self.inboxes.get((sender, receiver, label))

    def close(self) -> None:
        """Undeclare every token, publisher and subscriber (the node leaves the graph)."""
        for lane in self.publishers.values():
            lane.close()
        for inbox in self.inboxes.values():
            inbox.close()
        undeclare(self._node_token)
