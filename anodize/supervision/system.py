"""Systems: a global type, groups of roles, and how to run them.

:meth:`System.run` is the paper's primordial thread: it builds one channel per
ordered pair of roles that the global type connects, starts every group through
the transport's runner (threads, or one process per group) and hands the run to
the supervision core (:mod:`.supervisor`), which applies failure policies and
builds the :class:`RunReport`. ``run`` always returns a report.
"""

from __future__ import annotations

import os
from collections.abc import Callable

from sessiontypes import GlobalType
from sessiontypes.graph import communication_graph

from ..errors import AnodizeError, ConfigurationError
from .group import FailurePolicy, Group, parse_memory, reference_of, resolve_function
from .report import GroupStatus, RunReport
from .supervisor import Runner, Supervisor
from .threads import ThreadRunner

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
            raise ConfigurationError(f"transport {transport!r}: expected one of {', '.join(TRANSPORTS)}")
        self.global_type = global_type
        self.transport = transport
        self.monitors = monitors
        self.groups: dict[str, Group] = {}
        self._placed: dict[str, str] = {}

    def group(self, name: str, priority: int | None = None, memory: int | str | None = None,
              cpus: set[int] | frozenset[int] | None = None, on_failure: str = FailurePolicy.STOP,
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
            ConfigurationError: (a ``ValueError``) a duplicate name, a priority outside 1..99, a bad memory size,
                CPU set or failure policy.
        """
        if name in self.groups:
            raise ConfigurationError(f"group {name} is declared twice")
        if not isinstance(name, str) or not name.isprintable() or not name or any(
                c.isspace() or c == "/" for c in name):
            raise ConfigurationError(f"group name {name!r}: expected a non-empty name without spaces or '/'")
        if priority is not None and (isinstance(priority, bool) or not isinstance(priority, int)
                                     or not 1 <= priority <= 99):
            raise ConfigurationError(f"group {name}: priority must be 1..99, got {priority!r}")
        policy = FailurePolicy.parse(on_failure, name)
        if isinstance(max_restarts, bool) or not isinstance(max_restarts, int) or max_restarts < 0:
            raise ConfigurationError(f"group {name}: max_restarts must be an int >= 0, got {max_restarts!r}")
        if cpus is not None:
            cpus = frozenset(cpus)
            available = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else cpus
            if not cpus or not cpus <= available or any(isinstance(c, bool) for c in cpus):
                raise ConfigurationError(f"group {name}: cpus {sorted(cpus)} must be a non-empty subset of "
                                 f"the CPUs this process may use {sorted(available)}")
        group = Group(name, priority, parse_memory(memory), cpus or None, policy, max_restarts,
                      _system=self)
        self.groups[name] = group
        return group

    def _place(self, group: Group, role: str, function: object) -> None:
        # ``function`` is checked here, not trusted: Group.role passes on whatever it was given.
        if role not in self.global_type.roles:
            raise ConfigurationError(f"global {self.global_type.name} has no role {role}; expected one of "
                             f"{', '.join(self.global_type.roles)}")
        if role in self._placed:
            raise ConfigurationError(f"role {role} is already in group {self._placed[role]}")
        if isinstance(function, str):
            resolve_function(function)  # fail now, not in the group's process
        elif not callable(function):
            raise ConfigurationError(f"role {role}: expected a function, got {type(function).__name__}")
        if self.transport == "process":
            reference_of(function)  # another process must be able to import it
        self._placed[role] = group.name

    def run(self, timeout: float | None = None, grace: float = 2.0,
            on_status: Callable[[dict[str, GroupStatus]], None] | None = None,
            liveness: float = 2.0) -> RunReport:
        """Run every role to the end of its local type (or until ``timeout`` seconds).

        Roles still running at the timeout are stopped (``RoleStopped`` is raised in
        them at their next send or receive, or in ``Endpoint.sleep``) and reported as
        "stopped", with what each was waiting for. The timeout counts from when the
        roles start: with ``transport="process"``, once every group's process is ready.
        ``grace`` is how long they get to stop before their group is killed (process
        transport) or abandoned (inproc). Ctrl-C stops the run the same way and the
        report is marked interrupted. ``on_status``, if given, is called about twice a
        second with a :class:`GroupStatus` per group (from the supervising thread: keep
        it quick). With ``transport="process"`` a group that sends no heartbeat for
        ``liveness`` seconds (frozen, stopped, or in a call that holds the GIL) is failed
        and its policy applies.

        Raises:
            AnodizeError: some role of the global type is in no group.
        """
        if not liveness > 0:
            raise ConfigurationError(f"liveness {liveness!r}: expected a number of seconds > 0")
        gt = self.global_type
        missing = [r for r in gt.roles if r not in self._placed]
        if missing:
            raise AnodizeError(f"global {gt.name}: roles {', '.join(missing)} are in no group")
        machines = {role: gt.project(role).fsm() for role in gt.roles}
        channels = tuple(communication_graph(gt).edges)
        runner: Runner
        if self.transport == "process":
            from .processes import ProcessRunner  # the inproc path never needs it

            runner = ProcessRunner(gt.name, machines, channels, self.groups, self.monitors, liveness)
        else:
            runner = ThreadRunner(gt, machines, channels, self.groups, self.monitors)
        return Supervisor(gt.name, gt.roles, self.groups, channels, runner, timeout, grace, on_status).run()
