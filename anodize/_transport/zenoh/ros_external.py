"""Channels to and from external roles on Zenoh: roles that ROS 2 nodes on rmw_zenoh play.

A role listed in ``[ros] external`` runs in no group: a ROS 2 node publishes and
subscribes its topics. Every label it sends or receives is on a ROS topic (the system
checks that), so its channels are the topics alone, with no credits:

- :class:`ExternalSender` (a role here sends to the node) puts each message on its topic
  as rmw_zenoh does (:class:`~.ros_topics.RosPublisher`); back pressure is Zenoh's own
  (a reliable keep-all topic blocks when the network is congested).
- :class:`ExternalReceiver` (the node sends to a role here) takes each message from the
  topic the protocol says comes next (the channel's :class:`~anodize._transport.ros_lanes.LanePlan`),
  from the inbox of :class:`~.ros_topics.RosInbox`. A sample that is not the type's CDR, that
  comes under another type hash (a node built against another definition of the message)
  or without rmw_zenoh's attachment is handed on as :class:`~anodize._session.channel.Corrupt`:
  the receiver's monitor blames the external role, and nothing of it reaches the role.

Whether a node is there is read from rmw_zenoh's graph (:class:`RosGraph`, the liveliness
tokens under ``@ros2_lv/<domain>``): the start barrier waits (``wait``) until some other
node publishes each topic an external role sends on and subscribes each one it receives on
(:func:`wait_for_ros_nodes`); once the last publisher of a topic is gone, a receiver waiting
on it gets a :class:`~anodize._session.channel.PeerFailure`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from queue import Empty

from ..._ros.rmw_zenoh import ADMIN_SPACE, Entity, RmwZenohFormatError, parse_entity_key
from ..._session.channel import STOP, Corrupt, PeerFailure
from ...errors import AnodizeError
from ..links import LinkNetwork, PayloadError, StartBarrierError, WritingEnd
from ..ros_lanes import LanePlan
from .binding import Sample, Session, is_delete, key_of, undeclare, watch_tokens
from .flow import POLL
from .ros_topics import RosInbox, RosPublisher
from .settings import ZenohSettings

__all__ = ["RosGraph", "ExternalSender", "ExternalReceiver", "wait_for_ros_nodes", "MAX_ENTITIES"]

MAX_ENTITIES = 10_000  # tokens of other nodes kept; a ROS graph has far fewer, a hostile one no more


class RosGraph:
    """The entities of other sessions on rmw_zenoh's graph of one domain, kept up to date from
    their liveliness tokens (tokens that do not parse, and our own, are ignored)."""

    def __init__(self, session: Session, domain: int) -> None:
        self.own = str(session.zid())
        self.changed = threading.Condition()
        self._entities: dict[str, Entity] = {}
        self._watch = watch_tokens(session, f"{ADMIN_SPACE}/{domain}/**", self._on_token)

    def _on_token(self, sample: Sample) -> None:
        key = key_of(sample)
        with self.changed:
            if is_delete(sample):
                self._entities.pop(key, None)
            elif len(self._entities) < MAX_ENTITIES:
                try:
                    entity = parse_entity_key(key)
                except RmwZenohFormatError:
                    return
                if entity.zid != self.own:
                    self._entities[key] = entity
            self.changed.notify_all()

    def count(self, kind: str, topic: str) -> int:
        """How many entities of ``kind`` (``"MP"``, ``"MS"``) of other sessions are on ``topic``."""
        with self.changed:
            return sum(1 for e in self._entities.values()
                       if e.kind == kind and e.topic is not None and e.topic.name == topic)

    def close(self) -> None:
        undeclare(self._watch)


class ExternalSender(WritingEnd):
    """The writing end of a channel into an external role: its labels' ROS topics, no credits."""

    read_where = "by a ROS 2 node"

    def __init__(self, lanes: dict[str, RosPublisher], graph: RosGraph, sender: str, receiver: str) -> None:
        self.lanes = lanes
        self.graph = graph
        self.sender = sender
        self.receiver = receiver
        self.resent = 0

    @property
    def topics(self) -> list[str]:
        return sorted({lane.entity.topic.name for lane in self.lanes.values() if lane.entity.topic is not None})

    def put(self, item: object) -> None:
        """Put ``(label, payload)`` on the label's topic; a failure has nowhere to go (a ROS node
        reads only its topics).

        Raises:
            PayloadError: the payload is not a message of the topic's type (nothing was sent).
        """
        if type(item) is not tuple:
            return
        label, payload = item
        lane = self.lanes.get(label)
        if lane is None:
            raise PayloadError(f"role {self.sender}: {label} to external role {self.receiver} is on no ROS topic")
        try:
            cdr = lane.kind.serialize(payload)
        except AnodizeError as error:
            raise PayloadError(f"role {self.sender}: cannot send {label} to {self.receiver}: {error}") from None
        lane.put(cdr)

    def put_failure(self, cause: str) -> None:
        """Nothing: a ROS node is not told of failures."""

    def find_reader(self) -> bool:
        """Whether some other node subscribes each of the channel's topics (the start barrier)."""
        return all(self.graph.count("MS", topic) for topic in self.topics)

    def qsize(self) -> int:
        return 0

    def settle(self, linger: float) -> bool:
        return True

    def resend_if_stuck(self) -> None:
        """Nothing: Zenoh's reliability is all there is towards a ROS node."""

    def close(self) -> None:
        """Nothing: the group's ROS node undeclares its publishers."""


class ExternalReceiver:
    """The reading end of a channel from an external role: its labels' ROS topics, in the protocol's order."""

    def __init__(self, inboxes: dict[str, RosInbox], plan: LanePlan | None, graph: RosGraph,
                 network: LinkNetwork, sender: str, receiver: str) -> None:
        self.inboxes = inboxes
        self.by_topic = {inbox.topic.name: (label, inbox) for label, inbox in inboxes.items()}
        self.plan = plan
        self.state = plan.initial if plan is not None else 0
        self.graph = graph
        self.network = network
        self.sender = sender
        self.receiver = receiver
        self.frame_size = 0
        self.taken = 0
        self.duplicates = 0
        self.gaps = 0
        self._pushed: list[object] = []
        self._seen: set[str] = set()  # topics some node has published (at the barrier or since)
        self._lost: str | None = None

    def _due(self) -> tuple[str, RosInbox]:
        """The label and inbox of the topic the next message comes on."""
        if self.plan is not None:
            topic = self.plan.lanes[self.state]
            if topic is not None and topic in self.by_topic:
                return self.by_topic[topic]
        return next(iter(sorted(self.by_topic.items())))[1]

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
                return self._pushed.pop(0)
            label, inbox = self._due()
            left = POLL if deadline is None else min(POLL, deadline - time.monotonic())
            sample = inbox.take(max(0.0, left))
            if sample is not None:
                return self._hand_on(label, inbox, sample.payload, sample.problem)
            if self.network.stopping:
                return STOP
            failed = self.network.failed.get(self.sender)
            if failed is not None:
                return PeerFailure(self.sender, failed)
            lost = self._publisher_lost(inbox.topic.name)
            if lost is not None:
                self.network.note_failed(self.sender, lost)
                return PeerFailure(self.sender, lost)
            if deadline is not None and time.monotonic() >= deadline:
                raise Empty

    def _hand_on(self, label: str, inbox: RosInbox, payload: bytes, problem: str | None) -> object:
        topic = inbox.topic
        self.frame_size = len(payload)
        self.taken += 1
        if problem is not None:
            return Corrupt(f"a sample on ROS topic {topic.name}: {problem}")
        kind = inbox.kind
        try:
            value = kind.deserialize(payload)
        except AnodizeError as error:
            return Corrupt(f"a sample on ROS topic {topic.name} that is not a {kind.name}: {error}")
        if self.plan is not None:
            self.state = self.plan.after(self.state, label)
        return (label, value)

    def _publisher_lost(self, topic: str) -> str | None:
        if self._lost is None and topic in self._seen and not self.graph.count("MP", topic):
            self._lost = f"no ROS 2 node publishes {topic} any more"
        return self._lost

    def get_nowait(self) -> object:
        return self.get(timeout=0)

    def empty(self) -> bool:
        """True when nothing (no message, no failure, no stop) is waiting."""
        if self._pushed or self.network.stopping or self.sender in self.network.failed:
            return False
        return self._due()[1].empty()

    def qsize(self) -> int:
        return sum(inbox.qsize() for inbox in self.inboxes.values())

    def find_writer(self) -> bool:
        """Whether some other node publishes each of the channel's topics (the start barrier)."""
        found = True
        for topic in self.by_topic:
            if self.graph.count("MP", topic):
                self._seen.add(topic)
            else:
                found = False
        return found

    def credit(self) -> None:
        """Nothing: no credits towards a ROS node."""

    def wake(self) -> None:
        """Nothing: a waiting receive looks at failures and stops every :data:`~.flow.POLL` seconds."""

    def close(self) -> None:
        """Nothing: the group's ROS node undeclares its subscriptions."""


def wait_for_ros_nodes(settings: ZenohSettings, graph: RosGraph, senders: Sequence[ExternalSender],
                       receivers: Sequence[ExternalReceiver], wait: float) -> None:
    """Return once some ROS node publishes each topic an external role sends on and subscribes
    each one it receives on, or raise when ``wait`` seconds are over.

    Raises:
        StartBarrierError: naming the external roles and topics with no node.
    """
    deadline = time.monotonic() + wait
    while True:
        missing = [(r.sender, f"{r.sender}->{r.receiver} on ROS topic {t}") for r in receivers
                   for t in sorted(r.by_topic) if not r.find_writer() and not graph.count("MP", t)]
        missing += [(s.receiver, f"{s.sender}->{s.receiver} on ROS topic {t}") for s in senders for t in s.topics
                     if not graph.count("MS", t)]
        if not missing:
            return
        left = deadline - time.monotonic()
        if left <= 0:
            roles = sorted({role for role, _ in missing})
            domain = settings.ros.domain if settings.ros is not None else 0
            raise StartBarrierError(
                f"after {wait:g} s on Zenoh, no sign of external role{'s' if len(roles) > 1 else ''} "
                f"{', '.join(roles)} (a ROS 2 node on rmw_zenoh, ROS_DOMAIN_ID {domain}) "
                f"(for {'; '.join(text for _, text in missing)})")
        with graph.changed:
            graph.changed.wait(min(0.1, left))
