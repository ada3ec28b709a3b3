"""The DDS transport's links: every channel between groups is a DDS topic.

A group's :class:`~anodize._transport.network.GroupNetwork` links its channels to roles
of other groups (or to external roles, ROS 2 nodes) with :class:`DdsLinks`: a writer
(:class:`~.sender.DdsSender`) in the sender's group and a reader
(:class:`~.receiver.DdsReceiver`) in the receiver's, on the group's one participant.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Collection, Iterable, Mapping

from ..codec import Codec
from ..links import LinkNetwork
from .barrier import wait_for_peers
from .binding import DDSException, delete
from .qos import Endpoints
from .receiver import DdsReceiver
from .sender import DdsSender
from .settings import DdsSettings

__all__ = ["DdsLinks"]


class DdsLinks:
    """The links of one group's process with ``transport="dds"``.

    Args:
        settings: the run's DDS settings.
        group, incarnation: this group.
        report: called with a line for the group's report (e.g. a rejected writer).
    """

    def __init__(self, settings: DdsSettings, group: str, incarnation: int,
                 report: Callable[[str], None] = lambda line: None) -> None:
        self.settings = settings
        self.endpoints = Endpoints(settings, group, incarnation, report)
        self.senders: list[DdsSender] = []
        self.receivers: list[DdsReceiver] = []

    def pairs(self, local_roles: Collection[str], channels: Iterable[tuple[str, str]],
              dead: Mapping[str, str]) -> list[tuple[str, str]]:
        """Every channel between a role here and one elsewhere, unless either end is not there."""
        return [(sender, receiver) for sender, receiver in channels
                if (sender in local_roles) != (receiver in local_roles) and sender not in dead
                and receiver not in dead]

    def writer(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> DdsSender:
        channel = DdsSender(self.endpoints, codec, network, *pair)
        self.senders.append(channel)
        return channel

    def reader(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> DdsReceiver:
        channel = DdsReceiver(self.endpoints, codec, network, *pair)
        self.receivers.append(channel)
        return channel

    def silence(self, pair: tuple[str, str]) -> None:
        """Our receiver failed: delete its readers, so its writer sees them unmatched and stops."""
        for receiver in self.receivers:
            if (receiver.sender, receiver.receiver) == pair:
                receiver.silenced = True  # first: a take the deletion fails is then no one's fault
                for lane in receiver.lanes:
                    with contextlib.suppress(DDSException):
                        delete(lane.reader)

    def noted_failed(self, role: str) -> None:
        """Nothing to wake: a receiver looks at the network's failures between short waits."""

    def wake(self) -> None:
        """Nothing to wake: a receiver looks at the network's stop between short waits."""

    def wait_for_peers(self) -> None:
        """The start barrier (:func:`.barrier.wait_for_peers`) over this group's channels."""
        wait_for_peers(self.settings, self.senders, self.receivers)

    def close(self, linger: float) -> None:
        """Wait (bounded) until every sample written has been acknowledged, before the process ends
        (a lane where some reader did not acknowledge names the other readers in the report)."""
        for sender in self.senders:
            sender.settle(linger)
