"""Channel taps: what watches a run's channels (a recording, the live view), behind one protocol.

A tap has two halves. The supervisor's half (:class:`ChannelTap`) is handed to
``System.run(taps=[...])``; when the run begins it is told the run's shape
(:class:`TapRun`) and answers with a :class:`GroupTapPlan`: plain, picklable data
that travels to every group (a thread of this process, or a group's own process,
in its typed spec). There the plan opens the group's half (:class:`GroupTap`),
which wraps the channels it watches before the endpoints take them, and is closed
once every role of the group has ended. When the run is over the supervisor's half
says what it did, as notes for the report.

This module sits below supervision: supervision knows taps only by this protocol,
so it imports neither :mod:`anodize._recording` nor :mod:`anodize._live`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from sessiontypes import GlobalType, StateMachine

from ._session.channel import Channel

__all__ = ["ChannelTap", "GroupTapPlan", "GroupTap", "TapRun", "TapGroup"]


@dataclass(frozen=True)
class TapRun:
    """What a tap is told when a run begins.

    Attributes:
        global_type: the protocol the run follows.
        machines: every role's state machine (external roles' too).
        group_of: role -> group, for every role anodize runs (the others are external).
        topics: ``(sender, receiver, label) -> ROS topic`` of the labels the system names
            as ROS 2 topics (the others are the tap's to name).
        transport: the transport's kind (``"inproc"``, ``"process"`` or ``"dds"``).
        functions: role -> ``"module:function"`` of the roles that can be named so.
        qos: ROS topic -> the QoS it is offered with, as rosbag2's ``offered_qos_profiles``
            YAML, for the topics given one on DDS (the others: reliable, keep-all, volatile).
    """

    global_type: GlobalType
    machines: Mapping[str, StateMachine]
    group_of: Mapping[str, str]
    topics: Mapping[tuple[str, str, str], str]
    transport: str
    functions: Mapping[str, str]
    qos: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class TapGroup:
    """The group a :class:`GroupTapPlan` opens its tap in.

    Attributes:
        name: the group's name.
        incarnation: its start (0, then 1, 2, ... for each restart).
        protocol: the global type's name.
        machines: the state machines of the group's own roles.
        memory: the group's memory bound in bytes, or None.
    """

    name: str
    incarnation: int
    protocol: str
    machines: Mapping[str, StateMachine]
    memory: int | None = None


class GroupTap(Protocol):
    """A tap's half inside one group."""

    def attach(self, queues: dict[tuple[str, str], Channel]) -> None:
        """Wrap the channels it watches among the group's ``queues`` (in place), before any is used."""

    def close(self) -> None:
        """Every role of the group has ended: finish (flush, disconnect)."""


class GroupTapPlan(Protocol):
    """What a tap hands every group: picklable (it crosses into group processes)."""

    def open(self, group: TapGroup) -> GroupTap:
        """The tap's half in ``group``."""


class ChannelTap(Protocol):
    """A tap, as a run is given it: ``System.run(taps=[...])``."""

    def begin(self, run: TapRun) -> GroupTapPlan:
        """The run is about to start its groups: what each of them is to open."""

    def status(self, statuses: Mapping[str, Any]) -> None:
        """About twice a second: each group's :class:`~anodize.GroupStatus`, by name (keep it quick)."""

    def end(self) -> list[str]:
        """The run is over: finish, and say what was done (notes for the report)."""
