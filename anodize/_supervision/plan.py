"""A run's plan: everything a transport needs to build its runner, in one value."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from sessiontypes import GlobalType, StateMachine

from ..taps import GroupTapPlan, TapGroup
from .group import Group
from .rosbridge import RosBridge

__all__ = ["RunPlan"]


@dataclass(frozen=True)
class RunPlan:
    """One run of a system, as ``System.run`` hands it to the transport (``transport.runner(plan)``).

    Attributes:
        global_type: the protocol.
        machines: every role's state machine (external roles' too).
        channels: every ordered pair of roles the global type connects.
        groups: every group of the system, by name.
        group_of: role -> group, for every role anodize runs (the others are external).
        monitors: whether endpoints check the protocol at run time.
        capacities: channels that hold at most so many messages.
        ros: the system's ROS 2 side, or None.
        taps: what each group opens to tap its channels (a recording, the live view).
        params: role -> its parameters, checked: the keyword arguments its function is called with.
    """

    global_type: GlobalType
    machines: Mapping[str, StateMachine]
    channels: tuple[tuple[str, str], ...]
    groups: Mapping[str, Group]
    group_of: Mapping[str, str]
    monitors: bool = True
    capacities: Mapping[tuple[str, str], int] | None = None
    ros: RosBridge | None = None
    taps: tuple[GroupTapPlan, ...] = ()
    params: Mapping[str, Mapping[str, object]] | None = None

    @property
    def protocol(self) -> str:
        """The global type's name."""
        return self.global_type.name

    def tap_group(self, group: Group, incarnation: int) -> TapGroup:
        """What a tap is told of ``group`` when it opens there."""
        return TapGroup(group.name, incarnation, self.protocol,
                        {role: self.machines[role] for role in group.roles}, group.memory)
