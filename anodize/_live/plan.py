"""What the live view shows: every label of every channel, under its topic, and who taps it.

Each label is one Foxglove channel, under the ROS topic the system maps it to, else
``/anodize/<Sender>/<Receiver>/<label>`` (as a recording names it). A channel is
tapped where it is sent (what left the sender); a channel from an external role is
tapped where it arrives. Channels inside a group are shown too: the live view is a
window on the whole protocol, not only on what crosses groups.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from sessiontypes import Sort, StateMachine

from .._recording.plan import channel_labels, default_topic

__all__ = ["LivePlan", "LiveLabel", "live_plan", "STATUS_TOPIC"]

STATUS_TOPIC = "/anodize/status"  # the JSON channel of each group's state, rate and memory


@dataclass(frozen=True)
class LiveLabel:
    """One label of one channel, the sort it carries, and its topic."""

    sender: str
    receiver: str
    label: str
    sort: Sort | None
    topic: str


@dataclass(frozen=True)
class LivePlan:
    """A live run's plan (picklable: it travels in each group's spec).

    Attributes:
        socket: the UNIX socket where the supervisor takes what the groups tap.
        labels: every label of every channel; a label's index names it on the socket.
        group_of: role -> group, for every role anodize runs (the others are external).
        on_demand: a label is forwarded only while the supervisor wants it (:data:`~.wire.WANT`),
            and every label's messages are counted (introspection); else every one is (Foxglove).
    """

    socket: str
    labels: tuple[LiveLabel, ...]
    group_of: Mapping[str, str]
    on_demand: bool = False
    index: Mapping[tuple[str, str, str], int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "index", {(x.sender, x.receiver, x.label): i for i, x in enumerate(self.labels)})

    def tapped_here(self, roles: Iterable[str]) -> dict[tuple[str, str], str]:
        """The channels a group running ``roles`` taps: pair -> "send" or "recv"."""
        local = set(roles)
        found: dict[tuple[str, str], str] = {}
        for x in self.labels:
            if x.sender in local:
                found[(x.sender, x.receiver)] = "send"
            elif x.sender not in self.group_of and x.receiver in local:
                found[(x.sender, x.receiver)] = "recv"
        return found


def live_plan(socket: str, machines: Mapping[str, StateMachine], group_of: Mapping[str, str],
              ros_topics: Mapping[tuple[str, str, str], str], on_demand: bool = False) -> LivePlan:
    """The plan of a run whose roles run in ``group_of``'s groups (a role in none is external).

    Args:
        socket: the supervisor's UNIX socket.
        machines: every role's state machine.
        group_of: role -> group name, for every role anodize runs.
        ros_topics: ``(sender, receiver, label) -> ROS topic`` of the labels the system maps.
        on_demand: forward a label only while it is wanted (introspection).
    """
    labels = tuple(LiveLabel(*key, item.sort, ros_topics.get(key) or default_topic(*key))
                   for key, item in sorted(channel_labels(machines).items()))
    return LivePlan(socket, labels, dict(group_of), on_demand)
