"""Which channels of a run are ROS 2 topics, and which topic carries a channel's next message.

With ``transport="dds"`` a system may map the labels of its channels to ROS 2 topics
(``"Move->Gazebo" = "/cmd_vel"``). A mapped message is published as ROS 2 publishes
it: on the DDS topic ``rt/cmd_vel`` with the type ``geometry_msgs::msg::dds_::Twist_``
and plain CDR, so ROS 2 nodes see it, and a ROS 2 node may play a role (an *external*
role) by publishing and subscribing those topics.

A ROS topic carries one message type and no label, so one topic carries one label of
one channel. A channel whose labels go on several topics (``color`` on
``/camera/color/image_raw`` and ``depth`` on ``/camera/depth/image_raw``) loses the
order DDS keeps within one topic; the receiver then takes each message from the topic
the protocol says comes next. :func:`lane_plan` works that out once, from the
receiver's state machine restricted to the channel (every other action erased, then
made deterministic), and refuses a channel where two labels on different topics may
come next from the same point: their order could not be known.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from sessiontypes import StateMachine

from ..errors import ConfigurationError
from .lossy_lanes import check_lossy
from .qos_profiles import RELIABLE_KEEP_ALL, QosError, QosProfile

__all__ = ["RosTopic", "RosSettings", "LanePlan", "lane_plan", "ros_settings", "dds_topic_of", "check_topic_name",
           "DEFAULT_ROS_DOMAIN", "ROS_DOMAIN_ENV", "qos_key"]

ROS_DOMAIN_ENV = "ROS_DOMAIN_ID"  # as every ROS 2 node reads it
DEFAULT_ROS_DOMAIN = 0
_TOPIC = re.compile(r"/[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*")
_MAX_SUBSETS = 10_000  # states of a channel's determinised machine; protocols are far smaller


def check_topic_name(name: str) -> str | None:
    """Why ``name`` is not a ROS 2 topic name this transport accepts (absolute, no ``~`` or
    substitutions, no ``__`` and no trailing ``_`` in a token), or None if it is one."""
    if not isinstance(name, str) or not _TOPIC.fullmatch(name):
        return "expected an absolute ROS topic name such as \"/cmd_vel\" (tokens of letters, digits and '_')"
    if "__" in name or any(token.endswith("_") for token in name.split("/")):
        return "ROS topic names may not contain '__' or end a token with '_'"
    return None


def dds_topic_of(ros_name: str) -> str:
    """The DDS topic ROS 2 uses for a topic: ``/cmd_vel`` -> ``rt/cmd_vel``."""
    return "rt" + ros_name


@dataclass(frozen=True)
class RosTopic:
    """One label of one channel, published on a ROS 2 topic.

    Attributes:
        name: the ROS topic name, ``/cmd_vel``.
        type_name: the ROS message type, ``geometry_msgs/msg/Twist`` (the label's sort).
    """

    name: str
    type_name: str


@dataclass(frozen=True)
class LanePlan:
    """The topic of a channel's next message, state by state.

    Attributes:
        initial: the start state.
        lanes: for each state, the ROS topic of every label that may come next, or None
            for the channel's own anodize topic (unmapped labels; also a final state).
        steps: ``(state, label) -> state``.
    """

    initial: int
    lanes: tuple[str | None, ...]
    steps: Mapping[tuple[int, str], int]

    def after(self, state: int, label: str) -> int:
        """The state after ``label``; an unexpected label (the monitor's business) leaves it."""
        return self.steps.get((state, label), state)


@dataclass(frozen=True)
class RosSettings:
    """The ROS side of a DDS run (picklable: it travels in each group's spec).

    Attributes:
        domain: the DDS domain of the ROS topics (``ROS_DOMAIN_ID``, default 0).
        distro: the ROS 2 distribution whose message definitions are used.
        topics: ``(sender, receiver, label) -> RosTopic``.
        external: roles that ROS 2 nodes play (anodize runs no code for them).
        plans: for each channel with a mapped label, its :class:`LanePlan` (channels
            into an external role have none: nobody reads them here).
        qos: ROS topic name -> its QoS, for the topics given one (the others are reliable,
            keep-all, volatile: :data:`~.qos_profiles.RELIABLE_KEEP_ALL`).
    """

    domain: int
    distro: str
    topics: Mapping[tuple[str, str, str], RosTopic]
    external: frozenset[str] = frozenset()
    plans: Mapping[tuple[str, str], LanePlan] = field(default_factory=dict)
    qos: Mapping[str, QosProfile] = field(default_factory=dict)

    def qos_of(self, topic: str) -> QosProfile:
        """The QoS of a ROS topic (reliable, keep-all, volatile unless the system gives another)."""
        return self.qos.get(topic, RELIABLE_KEEP_ALL)

    def topic_of(self, sender: str, receiver: str, label: str) -> RosTopic | None:
        return self.topics.get((sender, receiver, label))

    def channel_topics(self, sender: str, receiver: str) -> dict[str, RosTopic]:
        """The mapped labels of a channel: label -> topic."""
        return {label: topic for (s, r, label), topic in self.topics.items() if (s, r) == (sender, receiver)}


def lane_plan(machine: StateMachine, sender: str, topic_of: Mapping[str, str], channel: str) -> LanePlan:
    """The lanes of the channel from ``sender`` into the role of ``machine``.

    Args:
        machine: the receiving role's state machine.
        sender: the sending role.
        topic_of: label -> ROS topic name, for the channel's mapped labels.
        channel: ``"Sender->Receiver"``, for messages.

    Raises:
        ConfigurationError: the channel's receives are spread over several parallel
            branches while its labels use several topics, or two labels on different
            topics may come next from one point of the protocol.
    """
    owners = [m for m in machine.with_branches() if any(k[0] == "recv" and k[1] == sender for t in m.table for k in t)]
    topics = {topic_of.get(label) for label in _labels(owners, sender)}
    if len(topics) <= 1:  # one lane whatever comes: no order to work out
        return LanePlan(0, (next(iter(topics), None),), {})
    if len(owners) > 1:
        raise ConfigurationError(f"channel {channel} is used in several parallel branches and its labels go on "
                                 "different topics: their order could not be known; put them on one")
    return _determinise(owners[0], sender, topic_of, channel)



def _labels(machines: list[StateMachine], sender: str) -> set[str]:
    return {k[2] for m in machines for t in m.table for k in t if k[0] == "recv" and k[1] == sender}


def _determinise(machine: StateMachine, sender: str, topic_of: Mapping[str, str], channel: str) -> LanePlan:
    """Subset construction over the channel's labels, every other action erased."""
    def closure(states: Iterable[int]) -> frozenset[int]:
        seen = set(states)
        stack = list(seen)
        while stack:
            for (action, peer, _), transition in machine.table[stack.pop()].items():
                if not (action == "recv" and peer == sender) and transition.target not in seen:
                    seen.add(transition.target)
                    stack.append(transition.target)
        return frozenset(seen)

    start = closure([machine.initial])
    index = {start: 0}
    pending = [start]
    lanes: list[str | None] = [None]
    steps: dict[tuple[int, str], int] = {}
    while pending:
        subset = pending.pop()
        number = index[subset]
        moves: dict[str, set[int]] = {}
        for state in subset:
            for (action, peer, label), transition in machine.table[state].items():
                if action == "recv" and peer == sender:
                    moves.setdefault(label, set()).add(transition.target)
        topics = {topic_of.get(label) for label in moves}
        if len(topics) > 1:
            shown = ", ".join(f"{label} ({topic_of.get(label) or 'not a ROS topic'})" for label in sorted(moves))
            raise ConfigurationError(f"channel {channel}: the next message may be any of {shown}; labels that can "
                                     "come next from one point must share a topic (a ROS topic carries one label), "
                                     "else their order could not be known")
        lanes[number] = next(iter(topics)) if topics else None
        for label, targets in moves.items():
            target = closure(targets)
            if target not in index:
                if len(index) >= _MAX_SUBSETS:
                    raise ConfigurationError(f"channel {channel}: its order of labels is too intricate to map "
                                             f"onto topics (over {_MAX_SUBSETS} states)")
                index[target] = len(index)
                lanes.append(None)
                pending.append(target)
            steps[(number, label)] = index[target]
    return LanePlan(0, tuple(lanes), steps)


def ros_settings(machines: Mapping[str, StateMachine], channels: Iterable[tuple[str, str]],
                 topics: Mapping[str, str], external: Iterable[str] = (), distro: str = "",
                 domain: int | None = None, qos: Mapping[str, QosProfile] | None = None) -> RosSettings:
    """Check a system's ROS topic map and work out its lanes.

    Args:
        machines: every role's state machine.
        channels: the ordered pairs of roles the global type connects.
        topics: ``"Sender->Receiver"`` (a channel with one label) or
            ``"Sender->Receiver:label"`` -> ROS topic name.
        external: roles ROS 2 nodes play.
        distro: the ROS 2 distribution ("" for anodize's default).
        domain: the ROS domain the system file gives, if any; ``ROS_DOMAIN_ID`` overrides it,
            and without either it is 0, as for every ROS 2 node.
        qos: ROS topic name (``"/scan"``) or channel (``"A->B"``, ``"A->B:label"``: each of its
            labels on a ROS topic) -> QoS; a topic's own entry wins over its channel's.

    Raises:
        ConfigurationError: naming the entry at fault and what was expected; a
            :class:`~.qos_profiles.QosError` for a QoS entry (a lossy QoS on a topic whose
            protocol cannot lose a message names the interaction that forbids it).
    """
    import os

    pairs = set(channels)
    labels: dict[tuple[str, str], dict[str, str | None]] = {}  # channel -> label -> ROS type (None: not one)
    for role, machine in machines.items():
        for transition in machine.all_transitions():
            if transition.action == "send" and transition.peer is not None:
                target = transition.sort.target if transition.sort is not None else None
                ros = target[4:] if target is not None and target.startswith("ros:") else None
                labels.setdefault((role, transition.peer), {})[transition.label] = ros
    mapped: dict[tuple[str, str, str], RosTopic] = {}
    used: dict[str, str] = {}
    for key, name in topics.items():
        sender, receiver, label = _parse_key(key)
        if (sender, receiver) not in pairs:
            raise ConfigurationError(f"ros topic {key!r}: the protocol has no channel {sender}->{receiver}")
        carried = labels.get((sender, receiver), {})
        if label is None:
            if len(carried) != 1:
                raise ConfigurationError(
                    f"ros topic {key!r}: channel {sender}->{receiver} carries the labels {', '.join(sorted(carried))}; "
                    f"a ROS topic carries one: map each, e.g. \"{sender}->{receiver}:{min(carried)}\"")
            label = next(iter(carried))
        if label not in carried:
            raise ConfigurationError(f"ros topic {key!r}: channel {sender}->{receiver} has no label {label}; "
                                     f"expected one of {', '.join(sorted(carried))}")
        problem = check_topic_name(name)
        if problem is not None:
            raise ConfigurationError(f"ros topic {key!r} = {name!r}: {problem}")
        type_name = carried[label]
        if type_name is None:
            raise ConfigurationError(f"ros topic {key!r}: label {label} does not carry a ROS message (its sort must "
                                     "be declared as \"ros:pkg/msg/Name\")")
        if name in used:
            raise ConfigurationError(f"ros topic {name} is given to both {used[name]} and {key}; a topic carries "
                                     "one label of one channel")
        used[name] = key
        mapped[(sender, receiver, label)] = RosTopic(name, type_name)
    outside = set(external)
    for role in sorted(outside):
        if role not in machines:
            raise ConfigurationError(f"external role {role}: the protocol has no such role")
        for (sender, receiver), carried in sorted(labels.items()):
            if role in (sender, receiver):
                missing = sorted(label for label in carried if (sender, receiver, label) not in mapped)
                if missing:
                    raise ConfigurationError(
                        f"external role {role}: label {missing[0]} of channel {sender}->{receiver} is on no ROS "
                        "topic; a ROS node can only play a role whose every message is on one")
    plans = {}
    for sender, receiver in {(s, r) for s, r, _ in mapped}:
        if receiver not in outside:
            plans[(sender, receiver)] = lane_plan(
                machines[receiver], sender,
                {label: t.name for (s, r, label), t in mapped.items() if (s, r) == (sender, receiver)},
                f"{sender}->{receiver}")
    given = _topic_qos(qos or {}, mapped)  # topic -> (QoS, the entry that gives it)
    for (sender, receiver, label), topic in mapped.items():
        if topic.name in given:
            plan = plans.get((sender, receiver))
            profile, key = given[topic.name]
            check_lossy(machines[receiver], sender, receiver, label, topic.name, profile, qos_key(key),
                        plan.steps if plan is not None else None)
    text = os.environ.get(ROS_DOMAIN_ENV, "").strip()
    if text:
        try:
            domain = int(text)
        except ValueError:
            raise ConfigurationError(f"{ROS_DOMAIN_ENV}={text!r}: expected a DDS domain id 0..232") from None
    elif domain is None:
        domain = DEFAULT_ROS_DOMAIN
    if not 0 <= domain <= 232:
        raise ConfigurationError(f"ROS domain {domain}: expected a DDS domain id 0..232")
    return RosSettings(domain, distro, mapped, frozenset(outside), plans,
                       {name: profile for name, (profile, _) in given.items()})


def qos_key(entry: str) -> str:
    """Where the system file gives a QoS entry: ``ros.qos."/scan"`` or ``channels."A->B".qos``."""
    return f'channels."{entry}".qos' if "->" in entry else f'ros.qos."{entry}"'


def _topic_qos(qos: Mapping[str, QosProfile],
               mapped: Mapping[tuple[str, str, str], RosTopic]) -> dict[str, tuple[QosProfile, str]]:
    """Each ROS topic given a QoS, with it and the entry that gives it (a topic's own entry wins
    over its channel's)."""
    found: dict[str, tuple[QosProfile, str]] = {}
    for entry, profile in sorted(qos.items(), key=lambda item: "->" not in item[0]):  # channels first
        if "->" not in entry:
            if not any(topic.name == entry for topic in mapped.values()):
                named = ", ".join(sorted(topic.name for topic in mapped.values())) or "none"
                raise QosError(qos_key(entry), f"no label of the protocol is on ROS topic {entry} "
                                               f"([ros.topics]); the topics are: {named}")
            found[entry] = (profile, entry)
            continue
        sender, receiver, label = _parse_key(entry)
        topics = [topic for (s, r, carried), topic in mapped.items()
                  if (s, r) == (sender, receiver) and label in (None, carried)]
        if not topics:
            raise QosError(qos_key(entry), f"channel {sender}->{receiver}" + (f" label {label}" if label else "")
                           + " is on no ROS topic ([ros.topics]); a QoS is a ROS topic's, and anodize's own "
                             "topics stay reliable and keep-all")
        for topic in topics:
            found[topic.name] = (profile, entry)
    return found


def _parse_key(key: str) -> tuple[str, str, str | None]:
    match = re.fullmatch(r"\s*(\w+)\s*->\s*(\w+)\s*(?::\s*(\w+)\s*)?", key)
    if match is None:
        raise ConfigurationError(f"ros topic {key!r}: expected \"Sender->Receiver\" or \"Sender->Receiver:label\"")
    return match.group(1), match.group(2), match.group(3)
