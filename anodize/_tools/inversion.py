"""Priority inversion before the run: where a higher-priority role can wait on a lower one.

:func:`inversion_report` reads a system file's protocol and groups (it imports no role
code), builds the waits-for graph of the global type (:mod:`.waits`) and finds the
shortest chains from every role (:mod:`.chains`): when a chain of waits (A waits on B, which waits on C,
through the protocol's states) leads from a role to a role of lower priority in
another group, that is an :class:`Inversion`. For each one it says which roles and
groups take part, their priorities and CPU sets, which other groups can preempt the
lower roles and so stretch the wait (a group whose priority lies between the waiting
role's and the preempted role's, on the same host, sharing a CPU with it; a group
with no CPU set may run on any), whether priority inheritance over channels could
cover it, and what remains unbounded.

A group without a priority runs under the normal scheduler, below every real-time
priority: it counts as priority 0 here. An external role (a ROS 2 node) has no
priority anodize knows, and a chain ends at it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import sessiontypes
from sessiontypes import GlobalType

from .chains import ChainSearch
from .config import ConfigError, GroupConfig, SystemConfig
from .waits import Wait, waits_for_graph

__all__ = ["Party", "Preemption", "Inversion", "InversionReport",
           "analyse_inversions", "inversion_report", "load_global"]


@dataclass(frozen=True)
class Party:
    """A role on a chain, with what its group gives it.

    Attributes:
        role: the role.
        group: its group, or None for an external role (a ROS 2 node).
        priority: the group's priority 1..99; None when it has none (normal scheduling)
            or the role is external.
        cpus: the CPUs the group may run on; None when it may run on any.
        host: the host the group runs on (``transport = "dds"``), None for this one.
        nice: with no priority, the group's nice value (None: none given).
    """

    role: str
    group: str | None
    priority: int | None
    cpus: tuple[int, ...] | None
    host: str | None
    nice: int | None = None

    @property
    def external(self) -> bool:
        """Whether a ROS 2 node outside anodize plays the role."""
        return self.group is None

    @property
    def rank(self) -> int:
        """The priority to compare: 0 for normal scheduling (below every real-time priority)."""
        return self.priority or 0

    def describe(self) -> str:
        """``Move (group control, priority 90, CPUs any)``."""
        if self.external:
            return f"{self.role} (external ROS 2 node, priority unknown)"
        return (f"{self.role} (group {self.group}, {_priority(self.priority, self.nice)}, "
                f"CPUs {_cpus(self.cpus)}{_host(self.host)})")


@dataclass(frozen=True)
class Preemption:
    """A group that can run instead of a lower role on the chain while the high role waits.

    Attributes:
        group: the preempting group.
        priority: its priority (between the preempted role's and the waiting role's).
        cpus: its CPU set, None for any.
        role: the role on the chain it can preempt.
    """

    group: str
    priority: int
    cpus: tuple[int, ...] | None
    role: str

    def __str__(self) -> str:
        return f"{self.group} (priority {self.priority}, CPUs {_cpus(self.cpus)}) over {self.role}"


@dataclass(frozen=True)
class Inversion:
    """A higher-priority role that can wait, directly or through a chain, on a lower one.

    Attributes:
        high: the role that waits.
        low: the lower-priority (or external) role it ends up waiting on.
        chain: the waits from ``high`` to ``low``, in order (the shortest such chain).
        parties: every role on the chain, ``high`` first and ``low`` last.
        preemptions: the groups that can preempt a role of the chain after ``high``
            (sorted by group, then role).
        uncoverable: why priority inheritance over channels cannot cover a link (an
            external role, a group on another host); empty when it could cover all.
        unbounded: what can stretch the wait without bound, as things are now.
        exact: False when the chain search gave up before finding the shortest chain that
            repeats no role (a large protocol, :data:`.chains.EXACT_SEARCH_WORK`): the chain
            shown is the shortest path, which passes through a role twice and so may be a wait
            that cannot happen.
    """

    high: Party
    low: Party
    chain: tuple[Wait, ...]
    parties: tuple[Party, ...]
    preemptions: tuple[Preemption, ...]
    uncoverable: tuple[str, ...]
    unbounded: tuple[str, ...]
    exact: bool = True

    @property
    def bounded(self) -> bool:
        """Whether nothing can stretch the wait without bound."""
        return not self.unbounded

    def lines(self) -> list[str]:
        """The inversion as an indented block of text."""
        chain = " -> ".join(f"{w.role} {w.action} [state {w.state}]" for w in self.chain)
        preempted = ("; ".join(map(str, self.preemptions))
                     or "no other group (none with a priority between theirs shares a CPU with them)")
        if self.uncoverable:
            inheritance = "cannot cover it: " + "; ".join(self.uncoverable)
        else:
            inheritance = "covers it (every link on one host, to a group anodize runs that accepts it); applied"
        unbounded = "; ".join(self.unbounded) or "nothing (the wait is bounded by the lower roles' own work)"
        kind = "unbounded" if self.unbounded else "bounded"
        lines = [f"{kind} inversion: {self.high.describe()} can wait on {self.low.describe()}",
                 f"  chain: {chain} -> {self.low.role}",
                 "  roles: " + ", ".join(p.describe() for p in self.parties),
                 f"  preempted by: {preempted}",
                 f"  priority inheritance: {inheritance}",
                 f"  unbounded: {unbounded}"]
        if not self.exact:
            lines.append("  note: the protocol is too large for the exact chain search; this chain passes "
                         "through a role twice and may not be a wait that can happen")
        return lines

    def to_dict(self) -> dict[str, Any]:
        """The inversion as JSON-ready values."""
        return {"high": self.high.role, "low": self.low.role, "bounded": self.bounded,
                "chain": [{"role": w.role, "state": w.state, "peer": w.peer, "kind": w.kind,
                           "action": w.action} for w in self.chain],
                "roles": [{"role": p.role, "group": p.group, "priority": p.priority,
                           "cpus": list(p.cpus) if p.cpus is not None else None, "host": p.host}
                          for p in self.parties],
                "preempted_by": [{"group": p.group, "priority": p.priority, "role": p.role,
                                  "cpus": list(p.cpus) if p.cpus is not None else None}
                                 for p in self.preemptions],
                "inheritance_could_cover": not self.uncoverable, "inheritance_uncoverable": list(self.uncoverable),
                "unbounded": list(self.unbounded), "exact": self.exact}


@dataclass(frozen=True)
class InversionReport:
    """What :func:`analyse_inversions` found.

    Attributes:
        inversions: by the waiting role's priority (highest first), then the lower role's.
        waits: how many waits the protocol has (states where a role can block on a peer).
        inheritance_applied: whether every group accepts priority inheritance (no group's
            table says ``priority_inheritance = false``).
    """

    inversions: tuple[Inversion, ...]
    waits: int
    inheritance_applied: bool

    @property
    def unbounded(self) -> tuple[Inversion, ...]:
        """The inversions that nothing bounds."""
        return tuple(i for i in self.inversions if not i.bounded)

    def lines(self) -> list[str]:
        """Every inversion's block, then a summary line."""
        found = [line for inversion in self.inversions for line in inversion.lines()]
        waits = f"{self.waits} {'wait' if self.waits == 1 else 'waits'}"
        if not self.inversions:
            return [*found, f"no priority inversion among {waits}"]
        count = len(self.inversions)
        inheritance = "applied" if self.inheritance_applied else "turned off in some groups"
        return [*found, (f"{count} priority {'inversion' if count == 1 else 'inversions'} "
                         f"({len(self.unbounded)} unbounded) among {waits}; priority inheritance is {inheritance}")]

    def to_dict(self) -> dict[str, Any]:
        """The report as JSON-ready values."""
        return {"waits": self.waits, "inheritance_applied": self.inheritance_applied,
                "inversions": [i.to_dict() for i in self.inversions]}


def inversion_report(config: SystemConfig) -> InversionReport:
    """Load the system file's protocol and analyse it with its groups.

    Raises:
        sessiontypes.ProtocolError: the protocol file has errors.
        ConfigError: the protocol cannot be read, has no such global, or a role of it is in no
            group and not external.
    """
    return analyse_inversions(config, load_global(config))


def load_global(config: SystemConfig) -> GlobalType:
    """The system file's global type, checked as :func:`.config.build_system` checks it.

    Raises:
        sessiontypes.ProtocolError: the protocol file has errors.
        ConfigError: the protocol cannot be read, has no such global, or a role of it is in no
            group and not external.
    """
    shown = str(config.path)
    try:
        module = sessiontypes.load(str(config.protocol))
    except OSError as error:
        raise ConfigError(shown, "protocol", f"cannot read {config.protocol}: {error.strerror or error}") from None
    if config.global_name not in module.globals:
        raise ConfigError(shown, "global", f"no global {config.global_name} in {config.protocol}; "
                                           f"expected one of {', '.join(module.globals) or '(none)'}")
    global_type = module.globals[config.global_name]
    missing = [r for r in global_type.roles if config.group_of(r) is None and r not in config.external]
    if missing:
        raise ConfigError(shown, "groups", f"{'role' if len(missing) == 1 else 'roles'} {', '.join(missing)} of "
                                           f"global {global_type.name} {'is' if len(missing) == 1 else 'are'} "
                                           "in no group")
    return global_type


def analyse_inversions(config: SystemConfig, global_type: GlobalType) -> InversionReport:
    """Every pair (higher role, lower role) where the first can wait on the second, with the
    shortest chain of waits between them.

    Args:
        config: the system file: groups (priorities, CPU sets, hosts), external roles and
            bounded channels (``[channels."A->B"] capacity``).
        global_type: its global type, whose roles are all in a group or external.
    """
    parties = {role: _party(role, config) for role in global_type.roles}
    capacities = {_channel(key): n for key, n in config.capacities.items()}
    machines = {role: global_type.project(role).fsm() for role in global_type.roles if role not in config.external}
    graph = waits_for_graph(machines, capacities)
    search = ChainSearch(graph)
    found: dict[tuple[str, str], tuple[Wait, ...]] = {}
    inexact: set[tuple[str, str]] = set()
    for role in sorted({wait.role for wait in graph.nodes}):
        chains = search.from_role(role)
        for peer, chain in chains.shortest.items():
            high, low = parties[role], parties[peer]
            if (low.external and high.priority is not None) or low.rank < high.rank:
                found[role, peer] = chain
                if peer in chains.inexact:
                    inexact.add((role, peer))
    order = sorted(found, key=lambda key: (-parties[key[0]].rank, key[0], -parties[key[1]].rank, key[1]))
    alone = {key: _inversion(found[key], parties, config, exact=key not in inexact) for key in order}
    inversions = []
    for (waiter, waited), inversion in alone.items():
        # the lower role's own waits stretch this one: unbounded if they are
        beyond = _beyond(found[waiter, waited], search)
        further = [role for role in beyond if (waiter, role) in alone and not alone[waiter, role].bounded]
        if further:
            reason = (f"{waited} can itself wait on {_and(further)}, and that is unbounded "
                      f"(see {_and([f'{waiter} -> {role}' for role in further])})")
            inversion = dataclasses.replace(inversion, unbounded=(*inversion.unbounded, reason))
        inversions.append(inversion)
    return InversionReport(tuple(inversions), graph.number_of_nodes(),
                           all(group.priority_inheritance for group in config.groups.values()))


def _beyond(chain: tuple[Wait, ...], search: ChainSearch) -> list[str]:
    """The roles the chain's last role can in turn wait on (through chains), sorted."""
    on_chain = {w.role for w in chain} | {chain[-1].peer}
    return sorted(search.from_waits((chain[-1],)).shortest.keys() - on_chain)


def _and(names: list[str]) -> str:
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def _inversion(chain: tuple[Wait, ...], parties: dict[str, Party], config: SystemConfig,
               exact: bool) -> Inversion:
    on_chain = tuple(parties[r] for r in (chain[0].role, *(w.peer for w in chain)))
    high, low = on_chain[0], on_chain[-1]
    preemptions = sorted({p for party in on_chain[1:] for p in _preemptions(party, high, config)},
                         key=lambda p: (p.group, p.role))
    uncoverable = []
    for wait in chain:
        waiter, peer = parties[wait.role], parties[wait.peer]
        if peer.external:
            uncoverable.append(f"{wait.role} waits on external ROS 2 node {peer.role}")
        elif peer.host != waiter.host:
            uncoverable.append(f"{wait.role} waits on group {peer.group} on {_host_name(peer.host)} "
                               f"across the network, from {_host_name(waiter.host)}")
        elif peer.group is not None and not config.groups[peer.group].priority_inheritance:
            uncoverable.append(f"{wait.role} waits on group {peer.group}, which turns it off "
                               "(priority_inheritance = false)")
    unbounded = [f"{peer.role} is an external ROS 2 node: its priority and timing are unknown"
                 for peer in on_chain[1:] if peer.external]
    unbounded += [f"{wait.peer} runs on {_host_name(parties[wait.peer].host)}: no inheritance crosses hosts"
                  for wait in chain
                  if not parties[wait.peer].external and parties[wait.peer].host != parties[wait.role].host]
    if uncoverable:  # inheritance (applied unless a group turns it off) bounds the rest
        unbounded += [f"{p.group} can preempt {p.role} for as long as it runs" for p in preemptions]
        unbounded += [f"{party.role} has no real-time priority: any process on the machine can delay it"
                      for party in on_chain[1:] if not party.external and party.priority is None]
    return Inversion(high, low, chain, on_chain, tuple(preemptions), tuple(uncoverable), tuple(unbounded), exact)


def _preemptions(party: Party, high: Party, config: SystemConfig) -> list[Preemption]:
    """Groups strictly between ``party``'s priority and ``high``'s, on its host and CPUs."""
    if party.external:
        return []
    return [Preemption(group.name, group.priority, group.cpus, party.role)
            for group in config.groups.values()
            if group.priority is not None and party.rank < group.priority < high.rank
            and group.host == party.host and _share_a_cpu(group.cpus, party.cpus)]


def _share_a_cpu(first: tuple[int, ...] | None, second: tuple[int, ...] | None) -> bool:
    return first is None or second is None or bool(set(first) & set(second))


def _party(role: str, config: SystemConfig) -> Party:
    name = config.group_of(role)
    if name is None:
        return Party(role, None, None, None, None)
    group: GroupConfig = config.groups[name]
    return Party(role, group.name, group.priority, group.cpus, group.host, group.nice)


def _channel(key: str) -> tuple[str, str]:
    sender, _, receiver = key.partition("->")
    return sender.strip(), receiver.strip()


def _priority(priority: int | None, nice: int | None = None) -> str:
    if priority is not None:
        return f"priority {priority}"
    return "no priority (normal scheduling)" if nice is None else f"no priority (normal scheduling, nice {nice})"


def _cpus(cpus: tuple[int, ...] | None) -> str:
    return "any" if cpus is None else ",".join(map(str, cpus))


def _host(host: str | None) -> str:
    return f", host {host}" if host is not None else ""


def _host_name(host: str | None) -> str:
    return f"host {host}" if host is not None else "this host"
