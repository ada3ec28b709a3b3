"""The Zenoh transport's links: every channel between groups is a key expression.

A group's :class:`~anodize._transport.network.GroupNetwork` links its channels to roles
of other groups with :class:`ZenohLinks`: a publisher (:class:`~.sender.ZenohSender`) in
the sender's group and a subscriber (:class:`~.receiver.ZenohReceiver`) in the
receiver's, on the group's one session (:class:`~.session.GroupSession`). A flow thread
sends, every :data:`~.flow.TICK`, the credits a receiver owes and what a sender must send
again (:mod:`.flow`), and pulls what a busy role has not read yet (:mod:`.receiver`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Collection, Iterable, Mapping

from ..codec import Codec
from ..links import LinkNetwork
from .barrier import wait_for_peers
from .binding import ZError
from .flow import TICK
from .receiver import ZenohReceiver
from .ros_external import ExternalReceiver, ExternalSender, RosGraph, wait_for_ros_nodes
from .ros_topics import RosTopicsNode
from .sender import ZenohSender
from .session import GroupSession
from .settings import ZenohSettings

__all__ = ["ZenohLinks"]


class ZenohLinks:
    """The links of one group's process with the Zenoh transport.

    Args:
        settings: the run's Zenoh settings.
        group, incarnation: this group.
        report: called with a line for the group's report (e.g. a rejected writer).
    """

    def __init__(self, settings: ZenohSettings, group: str, incarnation: int,
                 report: Callable[[str], None] = lambda line: None) -> None:
        self.settings = settings
        self.group = GroupSession(settings, group, incarnation, report)
        ros = settings.ros  # the group is a ROS 2 node on rmw_zenoh's graph if it sends on a ROS topic
        self.ros = None if ros is None or not ros.topics else RosTopicsNode(
            self.group.session, ros, group, [role for role, home in settings.group_of.items() if home == group])
        # Roles that ROS 2 nodes play: their channels are ROS topics alone (:mod:`.ros_external`).
        self.graph = RosGraph(self.group.session, ros.domain) if ros is not None and ros.external else None
        self.external_senders: list[ExternalSender] = []
        self.external_receivers: list[ExternalReceiver] = []
        self.senders: list[ZenohSender] = []
        self.receivers: list[ZenohReceiver] = []
        self._closing = threading.Event()
        self._flow = threading.Thread(target=self._tick, name="anodize-zenoh-flow", daemon=True)

    def pairs(self, local_roles: Collection[str], channels: Iterable[tuple[str, str]],
              dead: Mapping[str, str]) -> list[tuple[str, str]]:
        """Every channel between a role here and one elsewhere, unless either end is not there."""
        return [(sender, receiver) for sender, receiver in channels
                if (sender in local_roles) != (receiver in local_roles) and sender not in dead
                and receiver not in dead]

    def writer(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> ZenohSender | ExternalSender:
        if self.graph is not None and self.ros is not None and self.settings.is_external(pair[1]):
            external = ExternalSender(self.ros.lanes(*pair), self.graph, *pair)
            self.external_senders.append(external)
            return external
        channel = ZenohSender(self.group, codec, network, *pair)
        channel.ros = self.ros.lanes(*pair) if self.ros is not None else {}
        self.senders.append(channel)
        return channel

    def reader(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> ZenohReceiver | ExternalReceiver:
        ros = self.settings.ros
        if self.graph is not None and self.ros is not None and ros is not None and self.settings.is_external(pair[0]):
            external = ExternalReceiver(self.ros.inboxes_of(*pair), ros.plans.get(pair), self.graph, network, *pair)
            self.external_receivers.append(external)
            return external
        channel = ZenohReceiver(self.group, codec, network, *pair)
        self.receivers.append(channel)
        return channel

    def silence(self, pair: tuple[str, str]) -> None:
        """Our receiver failed: withdraw its token, so its sender sees it gone and stops."""
        for receiver in self.receivers:
            if (receiver.sender, receiver.receiver) == pair:
                receiver.close()

    def noted_failed(self, role: str) -> None:
        """Wake the receivers waiting on ``role``."""
        for receiver in self.receivers:
            if receiver.sender == role:
                receiver.wake()

    def wake(self) -> None:
        """The run is stopping: wake every receiver."""
        for receiver in self.receivers:
            receiver.wake()

    def wait_for_peers(self) -> None:
        """The start barrier (:func:`.barrier.wait_for_peers`), then the flow thread starts."""
        started = time.monotonic()
        wait_for_peers(self.group, self.senders, self.receivers)
        if self.graph is not None:
            wait_for_ros_nodes(self.settings, self.graph, self.external_senders, self.external_receivers,
                               max(0.0, self.settings.wait - (time.monotonic() - started)))
        for receiver in self.receivers:
            receiver.ticked = True  # their reading threads may now wait in recv(): the flow thread wakes them
        self._flow.start()

    def _tick(self) -> None:
        while not self._closing.wait(TICK):
            steps: list[Callable[[], None]] = [r.tick for r in self.receivers]
            steps += [s.resend_if_stuck for s in self.senders]
            for step in steps:
                try:
                    step()
                except ZError:
                    if self._closing.is_set():
                        return  # the session is closing
                    # one channel's put failed: the others' ticks (wakes, lost writers) still run

    def notes(self) -> list[str]:
        """What the group's report says of its channels: resends, duplicates, gaps."""
        resent = sum(sender.resent for sender in self.senders)
        dropped = sum(r.duplicates for r in self.receivers), sum(r.gaps for r in self.receivers)
        if not (resent or any(dropped)):
            return []
        return [(f"Zenoh: {resent} samples sent again, {dropped[0]} duplicates and {dropped[1]} out of order "
                "dropped (a link or router lost some)")]

    def close(self, linger: float) -> None:
        """Wait (bounded) until every sample put has been acknowledged, then close the session."""
        unsettled = [f"{s.sender}->{s.receiver}" for s in self.senders if not s.settle(linger)]
        if unsettled:
            self.group.report(f"Zenoh: what was put on {', '.join(unsettled)} was not all acknowledged "
                              f"within {linger:g} s of the end")
        self._closing.set()
        if self._flow.is_alive():
            self._flow.join(1.0)
        for receiver in self.receivers:
            receiver.close()
        for sender in self.senders:
            sender.close()
        if self.graph is not None:
            self.graph.close()
        if self.ros is not None:
            self.ros.close()
        self.group.close()
