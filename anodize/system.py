"""Systems: a global type, groups of roles, channels, and the supervisor.

:meth:`System.run` is the paper's primordial thread: it builds one channel
per ordered pair of roles that the global type connects, starts every role
on its own thread with its group's priority, and supervises. A role that
fails has its peers told at once (they get :class:`PeerFailedError` instead
of waiting); when the timeout passes, every role still running is stopped.
``run`` always returns a :class:`RunReport`.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterable
from queue import Empty, SimpleQueue
from typing import Any

from sessiontypes import GlobalType
from sessiontypes.graph import communication_graph

from .endpoint import Endpoint
from .errors import AnodizeError
from .group import FAILURE_POLICIES, Group, parse_memory, reference_of, resolve_function
from .report import GroupReport, GroupStatus, RoleReport, RunReport, Status
from .roles import describe_error, run_role
from .transport.inproc import InprocNetwork

__all__ = ["System"]

TRANSPORTS = ("inproc", "process")


class System:
    """A protocol and the groups that run its roles.

    Args:
        global_type: the checked global type every channel follows.
        transport: ``"inproc"`` (every role is a thread of this process) or
            ``"process"`` (each group is its own OS process; its roles are threads in it).
        monitors: False turns the run-time checks off (for measurements only).
    """

    def __init__(self, global_type: GlobalType, transport: str = "inproc", monitors: bool = True) -> None:
        if transport not in TRANSPORTS:
            raise ValueError(f"transport {transport!r}: expected one of {', '.join(TRANSPORTS)}")
        self.global_type = global_type
        self.transport = transport
        self.monitors = monitors
        self.groups: dict[str, Group] = {}
        self._placed: dict[str, str] = {}

    def group(self, name: str, priority: int | None = None, memory: int | str | None = None,
              cpus: set[int] | frozenset[int] | None = None, on_failure: str = "stop",
              max_restarts: int = 3) -> Group:
        """Declare a group; add its roles with ``.role(name, function)``.

        Args:
            priority: 1..99, SCHED_FIFO where permitted (else a nice value, reported).
            memory: a bound such as ``"64MiB"`` on what the group's roles allocate
                (enforced with ``transport="process"``).
            cpus: the CPUs the group may run on.
            on_failure: ``"stop"`` (the group stops, its peers get ``PeerFailedError``),
                ``"restart"`` (it starts again from its initial states, at most
                ``max_restarts`` times) or ``"stop-system"`` (every group stops).

        Raises:
            ValueError: a duplicate name, a priority outside 1..99, a bad memory size,
                CPU set or failure policy.
        """
        if name in self.groups:
            raise ValueError(f"group {name} is declared twice")
        if not isinstance(name, str) or not name.isprintable() or not name or any(
                c.isspace() or c == "/" for c in name):
            raise ValueError(f"group name {name!r}: expected a non-empty name without spaces or '/'")
        if priority is not None and (isinstance(priority, bool) or not isinstance(priority, int)
                                     or not 1 <= priority <= 99):
            raise ValueError(f"group {name}: priority must be 1..99, got {priority!r}")
        if on_failure not in FAILURE_POLICIES:
            raise ValueError(f"group {name}: on_failure must be one of {', '.join(FAILURE_POLICIES)}, "
                             f"got {on_failure!r}")
        if isinstance(max_restarts, bool) or not isinstance(max_restarts, int) or max_restarts < 0:
            raise ValueError(f"group {name}: max_restarts must be an int >= 0, got {max_restarts!r}")
        if cpus is not None:
            cpus = frozenset(cpus)
            available = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else cpus
            if not cpus or not cpus <= available or any(isinstance(c, bool) for c in cpus):
                raise ValueError(f"group {name}: cpus {sorted(cpus)} must be a non-empty subset of "
                                 f"the CPUs this process may use {sorted(available)}")
        group = Group(name, priority, parse_memory(memory), cpus or None, on_failure, max_restarts,
                      _system=self)
        self.groups[name] = group
        return group

    def _place(self, group: Group, role: str, function: Callable[..., Any]) -> None:
        if role not in self.global_type.roles:
            raise ValueError(f"global {self.global_type.name} has no role {role}; expected one of "
                             f"{', '.join(self.global_type.roles)}")
        if role in self._placed:
            raise ValueError(f"role {role} is already in group {self._placed[role]}")
        if isinstance(function, str):
            resolve_function(function)  # fail now, not in the group's process
        elif not callable(function):
            raise ValueError(f"role {role}: expected a function, got {type(function).__name__}")
        if self.transport == "process":
            reference_of(function)  # another process must be able to import it
        self._placed[role] = group.name

    def run(self, timeout: float | None = None, grace: float = 2.0,
            on_status: Callable[[dict[str, GroupStatus]], None] | None = None) -> RunReport:
        """Run every role to the end of its local type (or until ``timeout`` seconds).

        Roles still running at the timeout are stopped (``RoleStopped`` is raised in
        them at their next send or receive, or in ``Endpoint.sleep``) and reported as
        "stopped". The timeout counts from when the roles start: with
        ``transport="process"``, once every group's process is ready. ``grace`` is how
        long they get to stop before their group is killed (process transport) or
        abandoned (inproc). ``on_status``, if given, is called about twice a second
        with a :class:`GroupStatus` per group (from the supervising thread: keep it quick).

        Raises:
            AnodizeError: some role of the global type is in no group.
        """
        gt = self.global_type
        missing = [r for r in gt.roles if r not in self._placed]
        if missing:
            raise AnodizeError(f"global {gt.name}: roles {', '.join(missing)} are in no group")
        if self.transport == "process":
            from .supervisor import run_processes  # the inproc path never needs it
            return run_processes(self, timeout, grace, on_status)
        return self._run_inproc(timeout, grace, on_status)

    def _run_inproc(self, timeout: float | None, grace: float,
                    on_status: Callable[[dict[str, GroupStatus]], None] | None) -> RunReport:
        gt = self.global_type
        machines = {role: gt.project(role).fsm() for role in gt.roles}
        graph = communication_graph(gt)
        network = InprocNetwork(graph.edges, [r for r, m in machines.items() if m.forks])
        endpoints = {r: Endpoint(r, gt.name, machines[r], network, self.monitors) for r in gt.roles}
        results: SimpleQueue[RoleReport] = SimpleQueue()
        started = time.monotonic()
        threads = []
        for group in self.groups.values():
            for role, function in group.roles.items():
                if isinstance(function, str):
                    function = resolve_function(function)
                thread = threading.Thread(
                    target=run_role, name=f"anodize:{group.name}/{role}", daemon=True,
                    args=(group.name, group.priority, group.cpus, role, function, endpoints[role],
                          results.put))
                threads.append(thread)
        for thread in threads:
            thread.start()
        status = _InprocStatus(self.groups, endpoints, on_status) if on_status else None
        reports = self._supervise(results, network, len(threads), timeout, grace, started, status)
        sent = {(role, peer): n for role, ep in endpoints.items() for peer, n in ep.sent_counts().items()}
        report = self._report(reports, network, sent, time.monotonic() - started)
        if status is not None:
            status.final(report)
        return report

    def _supervise(self, results: SimpleQueue[RoleReport], network: InprocNetwork, count: int,
                   timeout: float | None, grace: float, started: float,
                   status: _InprocStatus | None) -> dict[str, RoleReport]:
        reports: dict[str, RoleReport] = {}
        deadline = None if timeout is None else started + timeout
        while len(reports) < count:
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                break
            wait = remaining if status is None else min(STATUS_INTERVAL, remaining or STATUS_INTERVAL)
            try:
                report = results.get(timeout=wait)
            except Empty:
                if status is not None:
                    status.tick(reports)
                continue
            reports[report.name] = report
            if report.status == "failed":
                network.fail(report.name, describe_error(report.error))
        if len(reports) < count:
            network.stop()
            end = time.monotonic() + grace
            while len(reports) < count and (left := end - time.monotonic()) > 0:
                try:
                    report = results.get(timeout=left)
                except Empty:
                    break
                reports[report.name] = report
        for role, group in self._placed.items():
            if role not in reports:  # did not reach a send or receive within the grace period
                reports[role] = RoleReport(role, group, "stopped", None, "")
        return reports

    def _report(self, reports: dict[str, RoleReport], network: InprocNetwork,
                sent: dict[tuple[str, str], int], duration: float) -> RunReport:
        roles = {r: reports[r] for r in self.global_type.roles}
        groups = {}
        for group in self.groups.values():
            status = group_status(roles[r].status for r in group.roles)
            scheduling = next((roles[r].scheduling for r in group.roles if roles[r].scheduling), "")
            note = ("not enforced: the inproc transport shares one heap (use transport='process')"
                    if group.memory else "")
            messages = sum(n for (a, _), n in sent.items() if a in group.roles)
            rate = messages / duration if duration > 0 else None
            groups[group.name] = GroupReport(
                group.name, status, scheduling, None, note, group.memory, messages=messages,
                rate_hz=rate)
        messages = {f"{a}->{b}": sent.get((a, b), 0) for a, b in network.queues}
        return RunReport(self.global_type.name, roles, groups, messages, duration, "inproc")


STATUS_INTERVAL = 0.5  # seconds between two on_status calls


def group_status(statuses: Iterable[str]) -> Status:
    """A group's status from its roles': failed > stopped > done."""
    seen = set(statuses)
    return "failed" if "failed" in seen else "stopped" if "stopped" in seen else "done"


class _InprocStatus:
    """Live status for the inproc transport: one shared process, so no pid or memory."""

    def __init__(self, groups: dict[str, Group], endpoints: dict[str, Endpoint],
                 on_status: Callable[[dict[str, GroupStatus]], None]) -> None:
        self.groups = groups
        self.endpoints = endpoints
        self.on_status = on_status
        self.last: dict[str, tuple[float, int]] = {}

    def tick(self, reports: dict[str, RoleReport]) -> None:
        now = time.monotonic()
        snapshot = {}
        for name, group in self.groups.items():
            sent = sum(sum(self.endpoints[r].sent_counts().values()) for r in group.roles)
            before = self.last.get(name)
            rate = (sent - before[1]) / (now - before[0]) if before and now > before[0] else None
            self.last[name] = (now, sent)
            done = [reports[r].status for r in group.roles if r in reports]
            state = group_status(done) if len(done) == len(group.roles) else "running"
            snapshot[name] = GroupStatus(name, state, messages=sent, rate_hz=rate)
        self.on_status(snapshot)

    def final(self, report: RunReport) -> None:
        self.on_status({name: GroupStatus(name, g.status, messages=g.messages)
                        for name, g in report.groups.items()})
