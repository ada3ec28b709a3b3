"""What a recorded run records: which channels, under which topics, at which end.

Every channel is recorded, those inside a group too, unless the run's
:class:`~.selection.RecordSelection` leaves some out; every label of it on its own MCAP
channel (a ROS topic carries one message type): under the ROS topic the system maps
it to, else ``/anodize/<Sender>/<Receiver>/<label>``. A channel is recorded where it
is sent, so what is recorded is what left the sender, numbered in the order it was
sent; a channel from an external role (a ROS node, which anodize does not run) is
recorded where it arrives.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from sessiontypes import Sort, StateMachine

from .._transport.ros_lanes import check_topic_name
from .selection import RecordSelection

__all__ = ["RecordPlan", "ChannelLabel", "record_plan", "default_topic", "channel_labels", "PROFILE", "META",
           "CLOCK_KEY", "CLOCK_TOPIC", "GAP_TOPIC", "GAP_KEY"]

PROFILE = "ros2"          # the MCAP profile rosbag2 writes
META = "anodize"          # prefix of anodize's keys in channel metadata, and its metadata record's name
CLOCK_TOPIC = "/anodize/clock/{role}"  # where a role's clock readings are recorded (no channel of the protocol)
CLOCK_KEY = f"{META}.clock"  # a clock channel's metadata key (its value: the role)
GAP_TOPIC = "/anodize/recording/gaps"  # where a part says which messages it could not record
GAP_KEY = f"{META}.gaps"  # the gap channel's metadata key (its value: "1")


@dataclass(frozen=True)
class ChannelLabel:
    """One label of one channel and the sort it carries."""

    sender: str
    receiver: str
    label: str
    sort: Sort | None


@dataclass(frozen=True)
class RecordPlan:
    """A recorded run's plan (picklable: it travels in each group's spec).

    Attributes:
        parts: the folder where each group writes its part of the recording.
        topics: ``(sender, receiver, label) -> topic`` for every recorded label.
        at_sender: channels recorded by the group that sends them.
        at_receiver: channels recorded by the group that receives them (external senders).
        group_of: role -> group, for the channel metadata.
        qos: ROS topic -> its ``offered_qos_profiles`` (rosbag2's YAML), where the run gave it a QoS.
        run_id: the run's random id, which each chain of the recording starts from (:mod:`.chain`).
    """

    parts: str
    topics: Mapping[tuple[str, str, str], str]
    at_sender: frozenset[tuple[str, str]]
    at_receiver: frozenset[tuple[str, str]]
    group_of: Mapping[str, str]
    qos: Mapping[str, str] = field(default_factory=dict)
    run_id: str = ""

    def recorded_here(self, roles: Iterable[str]) -> dict[tuple[str, str], str]:
        """The channels a group running ``roles`` records: pair -> "send" or "recv"."""
        local = set(roles)
        found = {pair: "send" for pair in self.at_sender if pair[0] in local}
        found.update({pair: "recv" for pair in self.at_receiver if pair[1] in local})
        return found


def channel_labels(machines: Mapping[str, StateMachine]) -> dict[tuple[str, str, str], ChannelLabel]:
    """Every label each channel carries, from the senders' state machines."""
    found: dict[tuple[str, str, str], ChannelLabel] = {}
    for role, machine in machines.items():
        for t in machine.all_transitions():
            if t.action == "send" and t.peer is not None:
                found.setdefault((role, t.peer, t.label), ChannelLabel(role, t.peer, t.label, t.sort))
    return found


def default_topic(sender: str, receiver: str, label: str) -> str:
    """``/anodize/<Sender>/<Receiver>/<label>``, made a valid ROS topic name if it is not one."""
    topic = f"/anodize/{sender}/{receiver}/{label}"
    if check_topic_name(topic) is None:
        return topic
    tokens = [re.sub(r"_+", "_", re.sub(r"\W", "_", t)).strip("_") or "x" for t in (sender, receiver, label)]
    return "/anodize/" + "/".join(t if t[0].isalpha() else f"n{t}" for t in tokens)


def record_plan(parts: str, machines: Mapping[str, StateMachine], group_of: Mapping[str, str],
                ros_topics: Mapping[tuple[str, str, str], str], inside: bool = True,
                selection: RecordSelection | None = None, qos: Mapping[str, str] | None = None) -> RecordPlan:
    """The plan of a run whose roles run in ``group_of``'s groups (a role in none is external).

    Args:
        parts: the folder for the groups' parts.
        machines: every role's state machine.
        group_of: role -> group name, for every role anodize runs.
        ros_topics: ``(sender, receiver, label) -> ROS topic`` of the labels the system maps.
        inside: record the channels inside each group too (each role can then be replayed alone);
            False: only those between groups. Ignored when ``selection`` is given.
        selection: which channels to record (default: every one ``inside`` allows).
        qos: ROS topic -> its ``offered_qos_profiles``, for the topics given a QoS.
    """
    chosen = selection if selection is not None else RecordSelection(inside=inside)
    labels = channel_labels(machines)
    recorded = {(s, r) for s, r, _ in labels if chosen.chooses((s, r), group_of)}
    topics = {key: ros_topics.get(key) or default_topic(*key) for key in labels if key[:2] in recorded}
    at_sender = frozenset(pair for pair in recorded if pair[0] in group_of)
    at_receiver = frozenset(pair for pair in recorded if pair[0] not in group_of and pair[1] in group_of)
    return RecordPlan(parts, topics, at_sender, at_receiver, dict(group_of), dict(qos or {}))
