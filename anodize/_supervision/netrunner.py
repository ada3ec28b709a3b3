"""What the runners of the network transports (:class:`~.ddsrunner.DdsRunner`,
:class:`~.zenohrunner.ZenohRunner`) share: this host's groups as processes, the rest elsewhere.

It is the process runner (:mod:`.processes`: isolation, memory bounds, priorities,
liveness of the local groups) without pipes: each group's process joins the run's
network with the transport's settings (:class:`~anodize._transport.links.NetworkSettings`)
and reports ready only once every peer has appeared (the start barrier). Groups placed on
other hosts are started there, by ``anodize run ... --host``; this host's report names
them as running elsewhere, and a link to their supervisors (when there are any) carries
what policies decide across hosts.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

from .._transport.links import NetworkSettings
from .hostview import LOST_AFTER
from .plan import RunPlan
from .processes import ProcessRunner
from .runner import Elsewhere, Link, Scope

__all__ = ["NetworkRunner"]


class NetworkRunner(ProcessRunner):
    """Starts this host's groups on a network transport; see the module docstring.

    Args:
        plan: the run; its groups are every group of the system.
        elsewhere: the groups of the system that run on other hosts, by name -> host.
        liveness: seconds a local group may send no heartbeat before it is failed.
        wait: seconds the start barrier may wait for other hosts (the start-up deadline allows for it).
    """

    def __init__(self, plan: RunPlan, elsewhere: Mapping[str, str], liveness: float, wait: float) -> None:
        self.everyone = dict(plan.groups)
        local = {name: g for name, g in self.everyone.items() if name not in elsewhere}
        super().__init__(replace(plan, groups=local), liveness)
        self.role_group = dict(plan.group_of)  # role -> group, for every group of the system
        self.elsewhere = dict(elsewhere)
        self.link: Any = None  # to the supervisors of the other hosts (see connect)
        # --wait alone bounds a group's start (its barrier counts from its process's start), plus 2 s
        # for the barrier's report of what is missing to arrive before this deadline fires.
        self.start_timeout = wait + 2.0
        self._local = local

    def connect(self, link: Link | None, lost_after: float = LOST_AFTER) -> None:
        """Policies that reach beyond a group act on the other hosts too, through ``link`` (None:
        every group is here); the runner's scope is this host's groups (call it once, from the
        subclass's constructor). A supervisor there unheard for ``lost_after`` seconds is lost."""
        self.link = link
        roles = self.scope.roles  # this host's (external roles are in no group)
        self.scope = Scope(self._local, roles,
                           tuple((a, b) for a, b in self.channels if a in roles and b in roles),
                           Elsewhere(link, self.everyone, self.channels, lost_after) if link is not None else None)

    def settings_for(self, group: str) -> NetworkSettings:
        """The transport's settings for one of this host's groups."""
        raise NotImplementedError

    def host_of(self) -> Mapping[str, str]:
        """group -> host, for every group of the system."""
        raise NotImplementedError

    def start(self, groups: Sequence[str], incarnation: int) -> None:
        """Start ``groups`` (of a batch that may span hosts); their channels to the other groups
        of the batch are on the network, to groups outside it gone (as with pipes)."""
        if self.link is not None and incarnation in self.link.batches:
            batch = self.link.batches[incarnation]
        else:  # every group starts as incarnation 0; with every group here, a restart's batch is ours
            batch = frozenset(self.host_of()) if incarnation == 0 else frozenset(groups)
        group_of = self.role_group
        for name in groups:
            dead = {role: f"group {group_of[role]} did not start again with group {name}"
                    for role in self.machines if role in group_of and group_of[role] not in batch}
            self._launch(name, incarnation, dead, {}, network=self.settings_for(name))

    def elsewhere_notes(self) -> list[str]:
        """The report's lines on the other hosts."""
        notes = []
        if self.elsewhere:
            notes.append("groups running elsewhere: " + ", ".join(
                f"{name} on host {host}" for name, host in sorted(self.elsewhere.items())))
        if self.link is not None:
            notes.extend(self.link.notes)
        return notes
