"""Systems: a global type, groups of roles, channels, and the supervisor.

:meth:`System.run` is the paper's primordial thread: it builds one channel
per ordered pair of roles that the global type connects, starts every role
on its own thread with its group's priority, and supervises. A role that
fails has its peers told at once (they get :class:`PeerFailedError` instead
of waiting); when the timeout passes, every role still running is stopped.
``run`` always returns a :class:`RunReport`.
"""

from __future__ import annotations

import inspect
import threading
import time
import typing
from collections.abc import Callable
from queue import Empty, SimpleQueue
from typing import Any

from sessiontypes import GlobalType
from sessiontypes.graph import communication_graph

from .endpoint import Endpoint, RoleStopped
from .errors import AnodizeError
from .group import Group, parse_memory
from .report import GroupReport, RoleReport, RunReport
from .sched import apply_thread_scheduling
from .transport.inproc import InprocNetwork
from .typed import State

__all__ = ["System"]

TRANSPORTS = ("inproc",)


class System:
    """A protocol and the groups that run its roles.

    Args:
        global_type: the checked global type every channel follows.
        transport: ``"inproc"`` (roles are threads of this process).
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
              cpus: set[int] | frozenset[int] | None = None) -> Group:
        """Declare a group; add its roles with ``.role(name, function)``.

        Raises:
            ValueError: a duplicate name, a priority outside 1..99, or a bad memory size.
        """
        if name in self.groups:
            raise ValueError(f"group {name} is declared twice")
        if priority is not None and not 1 <= priority <= 99:
            raise ValueError(f"group {name}: priority must be 1..99, got {priority}")
        group = Group(name, priority, parse_memory(memory), frozenset(cpus) if cpus else None,
                      _system=self)
        self.groups[name] = group
        return group

    def _place(self, group: Group, role: str, function: Callable[..., Any]) -> None:
        if role not in self.global_type.roles:
            raise ValueError(f"global {self.global_type.name} has no role {role}; expected one of "
                             f"{', '.join(self.global_type.roles)}")
        if role in self._placed:
            raise ValueError(f"role {role} is already in group {self._placed[role]}")
        if not callable(function):
            raise ValueError(f"role {role}: expected a function, got {type(function).__name__}")
        self._placed[role] = group.name

    def run(self, timeout: float | None = None, grace: float = 2.0) -> RunReport:
        """Run every role to the end of its local type (or until ``timeout`` seconds).

        Roles still running at the timeout are stopped (``RoleStopped`` is raised in
        them at their next send or receive) and reported as "stopped"; ``grace`` is how
        long they get to stop.

        Raises:
            AnodizeError: some role of the global type is in no group.
        """
        gt = self.global_type
        missing = [r for r in gt.roles if r not in self._placed]
        if missing:
            raise AnodizeError(f"global {gt.name}: roles {', '.join(missing)} are in no group")
        machines = {role: gt.project(role).fsm() for role in gt.roles}
        graph = communication_graph(gt)
        network = InprocNetwork(graph.edges, [r for r, m in machines.items() if _has_fork(m)])
        endpoints = {r: Endpoint(r, gt.name, machines[r], network, self.monitors) for r in gt.roles}
        results: SimpleQueue[RoleReport] = SimpleQueue()
        started = time.monotonic()
        threads = []
        for group in self.groups.values():
            for role, function in group.roles.items():
                thread = threading.Thread(target=_run_role, name=f"anodize:{group.name}/{role}",
                                          args=(group, role, function, endpoints[role], results),
                                          daemon=True)
                threads.append(thread)
        for thread in threads:
            thread.start()
        reports = self._supervise(results, network, len(threads), timeout, grace, started)
        sent = {(role, peer): n for role, ep in endpoints.items() for peer, n in ep.sent_counts().items()}
        return self._report(reports, network, sent, time.monotonic() - started)

    def _supervise(self, results: SimpleQueue[RoleReport], network: InprocNetwork, count: int,
                   timeout: float | None, grace: float, started: float) -> dict[str, RoleReport]:
        reports: dict[str, RoleReport] = {}
        deadline = None if timeout is None else started + timeout
        while len(reports) < count:
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                break
            try:
                report = results.get(timeout=remaining)
            except Empty:
                break
            reports[report.name] = report
            if report.status == "failed":
                network.fail(report.name, _describe(report.error))
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
            statuses = {roles[r].status for r in group.roles}
            status = "failed" if "failed" in statuses else "stopped" if "stopped" in statuses else "done"
            scheduling = next((roles[r].scheduling for r in group.roles if roles[r].scheduling), "")
            note = ("memory bound not enforced: the inproc transport shares one heap "
                    "(use transport='process')" if group.memory else "")
            groups[group.name] = GroupReport(group.name, status, scheduling, None, note)  # type: ignore[arg-type]
        messages = {f"{a}->{b}": sent.get((a, b), 0) for a, b in network.queues}
        return RunReport(self.global_type.name, roles, groups, messages, duration)


def _has_fork(machine: Any) -> bool:
    return bool(machine.forks)


def _describe(error: BaseException | None) -> str:
    return f"{type(error).__name__}: {error}" if error else "failed"


def _run_role(group: Group, role: str, function: Callable[..., Any], endpoint: Endpoint,
              results: SimpleQueue[RoleReport]) -> None:
    scheduling = ""
    try:
        scheduling = apply_thread_scheduling(group.priority, group.cpus)
        function(_argument_for(function, endpoint))
        unfinished = endpoint.unfinished()
        if unfinished:
            raise unfinished[0].end_violation()
    except RoleStopped:
        results.put(RoleReport(role, group.name, "stopped", None, scheduling))
    except BaseException as error:  # reported, never swallowed: the supervisor decides
        results.put(RoleReport(role, group.name, "failed", error, scheduling))
    else:
        results.put(RoleReport(role, group.name, "done", None, scheduling))


def _argument_for(function: Callable[..., Any], endpoint: Endpoint) -> Any:
    """The endpoint, or the typed initial state when the function asks for one."""
    try:
        parameters = list(inspect.signature(function).parameters.values())
        hints = typing.get_type_hints(function)
    except (TypeError, ValueError, NameError):
        return endpoint
    if not parameters:
        raise AnodizeError(f"role function {function.__qualname__} must take one argument "
                           "(an Endpoint or the typed initial state)")
    wanted = hints.get(parameters[0].name)
    if isinstance(wanted, type) and issubclass(wanted, State):  # a generated typed state
        return wanted(endpoint)
    return endpoint
