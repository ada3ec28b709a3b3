"""Systems: a global type, groups of roles, and how to run them.

:meth:`System.run` is the paper's primordial thread: it builds one channel per
ordered pair of roles that the global type connects, has the transport value
(:mod:`.transports`) build its runner from the run's plan (threads, one process
per group, or processes joined by DDS) and hands the run to the supervision core
(:mod:`.supervisor`), which applies failure policies and builds the
:class:`RunReport`. Channel taps (:mod:`anodize.taps`: a recording, the live view)
are handed to every runner the same way, in the plan. ``run`` always returns a report.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING

from sessiontypes import GlobalType, StateMachine
from sessiontypes.graph import communication_graph

from .._session.logs import LogEntry
from .._transport.spin import parse_spin
from ..errors import AnodizeError, ConfigurationError, ParameterError
from ..taps import ChannelTap, TapRun
from .group import FailurePolicy, Group, parse_memory, reference_of, resolve_function
from .legacy import legacy_run, legacy_system, legacy_taps
from .logfanout import log_receivers
from .params import ParamValue, check_params, check_value
from .plan import RunPlan
from .report import GroupStatus, RunReport, lossy_channels
from .rosbridge import RosBridge
from .rosnames import check_namespace
from .supervisor import Supervisor
from .transports import Dds, Inproc, Processes, Transport, Zenoh

if TYPE_CHECKING:
    from .._transport.ros_lanes import RosSettings

__all__ = ["System"]

_INPROC = Inproc()  # the default transport (a frozen value: one may be shared)


class System:
    """A protocol and the groups that run its roles.

    Args:
        global_type: the checked global type every channel follows.
        transport: what carries the messages: :class:`~anodize.Inproc` (every role is a
            thread of this process; the default), :class:`~anodize.Processes` (each group is
            its own OS process; its roles are threads in it) or :class:`~anodize.Dds` (as
            Processes, but channels between groups are DDS topics, so groups may run on
            several hosts). Each carries its own settings.
        monitors: False turns the run-time checks off (for measurements only).
        ros: :class:`~anodize.RosBridge`: channels named as ROS 2 topics (real topics on
            Dds; the names of their channels in recordings and the live view everywhere),
            and the roles ROS 2 nodes play (Dds only).
        capacities: ``{"Control->Move": 4}``: channels that hold at most so many messages;
            their senders wait while they are full (between threads of one process, and on
            DDS; between processes a channel's shared-memory ring bounds it instead, as the report says).
        params: ``{"Planner": {"speed": 0.3}}``: each role's parameters, given to its function as
            keyword arguments (it declares them: ``def planner(ep, *, speed: float = 0.35)``);
            bool, int, float, str or a list of one of them, as ROS parameters
            (docs/guide/system-files.md, "Parameters"). Checked against the functions when the
            system runs (:meth:`check_params` checks them sooner).
        domain, run_id, ros_topics, external, ros_distro, ros_domain: deprecated (with a
            ``transport`` string): the fields of ``Dds`` and ``RosBridge`` they now are.

    Raises:
        ConfigurationError: a transport or bridge that cannot be, naming what was expected.
    """

    def __init__(self, global_type: GlobalType, transport: Transport | str = _INPROC, monitors: bool = True, *,
                 ros: RosBridge | None = None, capacities: Mapping[str, int] | None = None,
                 params: Mapping[str, Mapping[str, ParamValue]] | None = None,
                 domain: int | None = None, run_id: str | None = None, ros_topics: Mapping[str, str] | None = None,
                 external: Iterable[str] | None = None, ros_distro: str | None = None,
                 ros_domain: int | None = None) -> None:
        old = (domain, run_id, ros_topics, external, ros_distro, ros_domain)
        if isinstance(transport, str):
            transport, old_ros = legacy_system(transport, *old)
            if old_ros is not None and ros is not None:
                raise ConfigurationError("ros=RosBridge(...) and the ros_topics, external, ros_distro or ros_domain "
                                         "keywords it replaces: give the RosBridge alone")
            ros = ros if old_ros is None else old_ros
        elif any(x is not None for x in old):
            raise ConfigurationError("domain, run_id, ros_topics, external, ros_distro and ros_domain are the "
                                     "fields of Dds(...) and RosBridge(...): give them there, not beside "
                                     f"transport={transport!r}")
        if not isinstance(transport, Inproc | Processes | Dds | Zenoh):
            raise ConfigurationError(f"transport: expected Inproc(), Processes(...), Dds(...) or Zenoh(...), "
                                     f"got {transport!r}")
        if ros is not None and not isinstance(ros, RosBridge):
            raise ConfigurationError(f"ros: expected RosBridge(...) or None, got {ros!r}")
        self.global_type = global_type
        self.transport: Transport = transport
        self.monitors = monitors
        self.ros = ros
        self.capacities = _capacities(global_type, capacities or {})
        external_roles = ros.external if ros is not None else frozenset()
        unknown = sorted(external_roles - set(global_type.roles))
        if unknown:
            raise ConfigurationError(f"external role {unknown[0]}: global {global_type.name} has no such role; "
                                     f"expected one of {', '.join(global_type.roles)}")
        if external_roles and not isinstance(transport, Dds | Zenoh):
            raise ConfigurationError(f"external roles ({', '.join(sorted(external_roles))}) are ROS 2 nodes: they "
                                     f"need transport Dds(...) or Zenoh(...), not {transport!r}")
        self.external = external_roles
        self.params = _params(global_type, params or {})
        self.groups: dict[str, Group] = {}
        self._placed: dict[str, str] = {}

    def group(self, name: str, priority: int | None = None, memory: int | str | None = None,
              cpus: set[int] | frozenset[int] | None = None, on_failure: str = FailurePolicy.STOP,
              max_restarts: int = 3, host: str | None = None, priority_inheritance: bool = True,
              nice: int | None = None, namespace: str = "", spin: int | str | None = None) -> Group:
        """Declare a group; add its roles with ``.role(name, function)``.

        Args:
            priority: 1..99, SCHED_FIFO where permitted (else a nice value, reported).
            memory: a bound such as ``"64MiB"`` on what the group's roles allocate
                (enforced with ``Processes`` and ``Dds``).
            cpus: the CPUs the group may run on.
            on_failure: ``"stop"`` (the group stops, its peers get ``PeerFailedError``),
                ``"restart"`` (it starts again from its initial states, at most
                ``max_restarts`` times) or ``"stop-system"`` (every group stops).
            host: on :class:`~anodize.Dds`, the host it runs on (see ``Dds.host``).
            priority_inheritance: while a role of a higher priority waits on one of this
                group's roles (a receive from it, a send to it on a full channel), that role's
                thread runs at the waiter's priority (docs/guide/priority-inheritance.md).
                False: this group always runs at its own priority.
            nice: with no ``priority``, ordinary scheduling (SCHED_OTHER) at this nice value,
                -20..19: below every real-time group, yet a larger share of the CPU than
                ordinary work at nice 0 (TinMan's simulated world runs so: it must not be starved
                by the machine's other work, nor run real time, as its renderer fills a CPU).
            namespace: the ROS namespace the relative topic names its roles publish resolve in:
                relative (``"planning"``) under the system's (``RosBridge.namespace``), or absolute.
            spin: on :class:`~anodize.Processes`, how long a receiver of this group may poll for a
                message before it sleeps: a duration such as ``"50us"`` (at most ``"1ms"``) or an int
                of microseconds; None or 0: never (docs/guide/spinning.md). Adaptive, bounded to a
                share of a CPU, and refused to a SCHED_FIFO group sharing a CPU with another group.

        Raises:
            ConfigurationError: (a ``ValueError``) a duplicate name, a priority outside 1..99, a nice
                value outside -20..19 or beside a priority, a bad memory size, CPU set, failure policy
                or spin.
        """
        if name in self.groups:
            raise ConfigurationError(f"group {name} is declared twice")
        if not isinstance(name, str) or not name.isprintable() or not name or any(
                c.isspace() or c == "/" for c in name):
            raise ConfigurationError(f"group name {name!r}: expected a non-empty name without spaces or '/'")
        if priority is not None and (isinstance(priority, bool) or not isinstance(priority, int)
                                     or not 1 <= priority <= 99):
            raise ConfigurationError(f"group {name}: priority must be 1..99, got {priority!r}")
        if nice is not None and (isinstance(nice, bool) or not isinstance(nice, int) or not -20 <= nice <= 19):
            raise ConfigurationError(f"group {name}: nice must be an int -20..19, got {nice!r}")
        if nice is not None and priority is not None:
            raise ConfigurationError(f"group {name}: priority {priority} (SCHED_FIFO) and nice {nice} (ordinary "
                                     "scheduling) exclude each other: give one")
        policy = FailurePolicy.parse(on_failure, name)
        if isinstance(max_restarts, bool) or not isinstance(max_restarts, int) or max_restarts < 0:
            raise ConfigurationError(f"group {name}: max_restarts must be an int >= 0, got {max_restarts!r}")
        if cpus is not None:
            cpus = frozenset(cpus)
            available = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else cpus
            if not cpus or not cpus <= available or any(isinstance(c, bool) for c in cpus):
                raise ConfigurationError(f"group {name}: cpus {sorted(cpus)} must be a non-empty subset of "
                                 f"the CPUs this process may use {sorted(available)}")
        if host is not None and (not isinstance(host, str) or not host.isidentifier()):
            raise ConfigurationError(f"group {name}: host {host!r}: expected a name such as robot or base_1")
        if not isinstance(priority_inheritance, bool):
            raise ConfigurationError(f"group {name}: priority_inheritance must be True or False, "
                                     f"got {priority_inheritance!r}")
        problem = check_namespace(namespace)
        if problem is not None:
            raise ConfigurationError(f"group {name}: namespace {namespace!r}: {problem}")
        try:
            spin_nanos = parse_spin(spin)
        except ConfigurationError as error:
            raise ConfigurationError(f"group {name}: {error}") from None
        group = Group(name, priority, parse_memory(memory), cpus or None, policy, max_restarts, host,
                      priority_inheritance=priority_inheritance, nice=nice, namespace=namespace, spin=spin_nanos,
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
        if role in self.external:
            raise ConfigurationError(f"role {role} is external (a ROS 2 node plays it): it runs in no group")
        if isinstance(function, str):
            resolve_function(function)  # fail now, not in the group's process
        elif not callable(function):
            raise ConfigurationError(f"role {role}: expected a function, got {type(function).__name__}")
        if not isinstance(self.transport, Inproc):
            reference_of(function)  # another process must be able to import it
        self._placed[role] = group.name

    def run(self, timeout: float | None = None, grace: float = 2.0,
            on_status: Callable[[dict[str, GroupStatus]], None] | None = None, *,
            taps: Sequence[ChannelTap] = (), liveness: float | None = None, host: str | None = None,
            wait: float | None = None, record: str | os.PathLike[str] | None = None,
            live: ChannelTap | None = None, stop_when: Callable[[], str | None] | None = None,
            on_log: Callable[[Sequence[LogEntry]], None] | None = None) -> RunReport:
        """Run every role to the end of its local type (or until ``timeout`` seconds).

        Roles still running at the timeout are stopped (``RoleStopped`` is raised in
        them at their next send or receive, or in ``Endpoint.sleep``) and reported as
        "stopped", with what each was waiting for. The timeout counts from when the
        roles start: with processes, once every group's process is ready. ``grace`` is
        how long they get to stop before their group is killed (processes) or abandoned
        (inproc). Ctrl-C stops the run the same way and the report is marked
        interrupted. ``on_status``, if given, is called about twice a second with a
        :class:`GroupStatus` per group (from the supervising thread: keep it quick).
        ``stop_when``, if given, is asked as often (also from that thread, also quick) and
        stops the run as the timeout does when it returns a reason, which the report's notes
        give ("stopping every group: the patrol is done"): how a caller that knows its
        mission is done, e.g. from what the roles wrote, ends a run whose roles loop forever.
        ``on_log``, if given, is handed the records the roles log (``ep.logger``, or any
        ``logging`` logger on a role's thread) as they reach the supervisor, in batches, from
        the same thread (keep it quick); every tap with a ``log`` method gets them too, and the
        report counts them (docs/guide/logging.md).
        What only some transports have (liveness, hosts, the start barrier) are fields
        of the transport value.

        ``taps`` watch every channel as the run goes, each the same way on every
        transport (:mod:`anodize.taps`): ``anodize._recording.Recording(path)`` writes every
        message between groups to a recording (docs/recording.md), an
        ``anodize._live.open_live_view()`` serves every channel and each group's status to
        the Foxglove app; the report's notes say what each did.

        ``liveness``, ``host``, ``wait``, ``record`` and ``live`` are deprecated: the
        transport's fields and ``taps`` now (docs/guide/transports.md).

        Raises:
            AnodizeError: some role of the global type is in no group.
            ConfigurationError: a transport that cannot run this system (e.g. a host no group runs on).
        """
        transport = legacy_run(self.transport, liveness, host, wait)
        taps = [*legacy_taps(record, live), *taps]
        gt = self.global_type
        missing = [r for r in gt.roles if r not in self._placed and r not in self.external]
        if missing:
            raise AnodizeError(f"global {gt.name}: roles {', '.join(missing)} are in no group")
        machines = {role: gt.project(role).fsm() for role in gt.roles}
        channels = tuple(communication_graph(gt).edges)
        bridge = self.resolved_ros()
        params = self.check_params()  # before the taps open: a refused parameter leaves no file behind
        topics = bridge.topic_names(machines, channels) if bridge is not None else {}
        ros = self.ros_settings(machines, channels)  # the QoS of its topics: on the wire, recorded, lost counted
        shape = TapRun(gt, machines, dict(self._placed), topics, transport.kind, self._functions(),
                       {name: profile.yaml() for name, profile in ros.qos.items()} if ros is not None else {})
        opened = tuple(tap.begin(shape) for tap in taps)
        if taps:
            on_status = _with_tap_status(on_status, taps)
        plan = RunPlan(gt, machines, channels, dict(self.groups), dict(self._placed), self.monitors,
                       dict(self.capacities), bridge, opened, params)
        runner = transport.runner(plan)
        scope = runner.scope
        fanout = log_receivers(on_log, taps, runner)
        report = Supervisor(gt.name, scope.roles, scope.groups, scope.channels, runner, timeout, grace, on_status,
                            scope.elsewhere, stop_when, on_log=fanout).run()
        notes = [note for tap in taps for note in tap.end()] + (fanout.problems if fanout is not None else [])
        lossy = lossy_channels(ros, scope.roles)
        notes.extend(f"{channel} may lose messages: {what}" for channel, what in lossy.items())
        return dataclasses.replace(report, capacities={f"{a}->{b}": n for (a, b), n in self.capacities.items()},
                                   notes=(*report.notes, *notes), lost={
                                       c: max(0, report.messages.get(c, 0) - report.received.get(c, 0)) for c in lossy})

    def check_params(self) -> dict[str, dict[str, ParamValue]]:
        """Each placed role's parameters, checked against its function (an int given for a
        declared float becomes a float).

        Raises:
            ParameterError: a role given parameters is in no group, its function takes no
                such parameter, a value is not of the declared type, or a keyword-only
                parameter without a default has no value.
        """
        functions = {role: function for group in self.groups.values() for role, function in group.roles.items()}
        checked: dict[str, dict[str, ParamValue]] = {}
        for role in self.params:
            if role not in functions:
                raise ParameterError(role, "", "it is in no group, so it takes no parameters (an external role "
                                               "is a ROS 2 node: give it its parameters there)")
        for role, function in functions.items():
            target = resolve_function(function) if isinstance(function, str) else function
            values = check_params(role, target, self.params.get(role, {}))
            if values:
                checked[role] = values
        return checked

    def _functions(self) -> dict[str, str]:
        """role -> ``module:function`` of the roles that can be named so (a recording keeps them for replay)."""
        functions = {}
        for group in self.groups.values():
            for role, function in group.roles.items():
                with contextlib.suppress(AnodizeError):  # a lambda (inproc) cannot be named: replay needs it given
                    functions[role] = reference_of(function)
        return functions

    def ros_settings(self, machines: dict[str, StateMachine] | None = None,
                     channels: tuple[tuple[str, str], ...] | None = None) -> RosSettings | None:
        """The checked ROS side of the system on Dds (None without a bridge, or on another transport).

        Raises:
            ConfigurationError: a topic entry or an external role that cannot be, naming it.
        """
        ros = self.resolved_ros()
        if ros is None or not (ros.topics or ros.external) or not isinstance(self.transport, Dds):
            return None
        gt = self.global_type
        machines = machines if machines is not None else {role: gt.project(role).fsm() for role in gt.roles}
        channels = channels if channels is not None else tuple(communication_graph(gt).edges)
        return ros.settings(machines, channels)

    def resolved_ros(self) -> RosBridge | None:
        """The bridge with every topic fully qualified (namespaces, then remaps), or None.

        Raises:
            ConfigurationError: a remap whose source is no topic of the system.
        """
        if self.ros is None:
            return None
        return self.ros.resolved({role: self.groups[group].namespace for role, group in self._placed.items()})


def _with_tap_status(on_status: Callable[[dict[str, GroupStatus]], None] | None,
                     taps: Sequence[ChannelTap]) -> Callable[[dict[str, GroupStatus]], None]:
    """``on_status`` that also hands the statuses to the taps (the live view publishes them)."""
    def each(statuses: dict[str, GroupStatus]) -> None:
        for tap in taps:
            tap.status(statuses)
        if on_status is not None:
            on_status(statuses)
    return each


def _params(global_type: GlobalType,
            given: Mapping[str, Mapping[str, ParamValue]]) -> dict[str, dict[str, ParamValue]]:
    """``{"Role": {"name": value}}`` checked against the protocol's roles and ROS's parameter types.

    Raises:
        ConfigurationError: not a role of the global type, or not a parameter value.
    """
    if not isinstance(given, Mapping):
        raise ConfigurationError(f'params: expected a mapping such as {{"Planner": {{"speed": 0.3}}}}, got {given!r}')
    found: dict[str, dict[str, ParamValue]] = {}
    for role, values in given.items():
        if role not in global_type.roles:
            raise ParameterError(role, "", f"global {global_type.name} has no such role, so it takes no parameters; "
                                           f"expected one of {', '.join(global_type.roles)}")
        if not isinstance(values, Mapping):
            raise ParameterError(role, "", f'expected a mapping of its parameters such as {{"speed": 0.3}}, '
                                           f"got {values!r}")
        found[role] = {str(name): check_value(role, str(name), value) for name, value in values.items()}
    return found


def _capacities(global_type: GlobalType, given: Mapping[str, int]) -> dict[tuple[str, str], int]:
    """``{"A->B": n}`` checked against the protocol's channels.

    Raises:
        ConfigurationError: not a channel of the protocol, or not a whole number >= 1.
    """
    channels = set(communication_graph(global_type).edges)
    found: dict[tuple[str, str], int] = {}
    for key, capacity in given.items():
        match = re.fullmatch(r"\s*(\w+)\s*->\s*(\w+)\s*", key)
        if match is None or (match.group(1), match.group(2)) not in channels:
            raise ConfigurationError(f"capacity of {key!r}: global {global_type.name} has no channel {key}; its "
                                     f"channels are {', '.join(sorted(f'{a}->{b}' for a, b in channels))}")
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 1:
            raise ConfigurationError(f"capacity of {key}: expected a whole number of messages >= 1, got {capacity!r}")
        found[(match.group(1), match.group(2))] = capacity
    return found
