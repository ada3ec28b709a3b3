"""Systems: a global type, groups of roles, and how to run them.

:meth:`System.run` is the paper's primordial thread: it builds one channel per
ordered pair of roles that the global type connects, starts every group through
the transport's runner (threads, or one process per group) and hands the run to
the supervision core (:mod:`.supervisor`), which applies failure policies and
builds the :class:`RunReport`. ``run`` always returns a report.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
import socket
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from sessiontypes import GlobalType, StateMachine
from sessiontypes.graph import communication_graph

from .._extras import import_extra
from ..errors import AnodizeError, ConfigurationError
from ..live.plan import LivePlan, live_plan
from ..recording.plan import RecordPlan, record_plan
from ..recording.run import RecordedRun
from .group import FailurePolicy, Group, parse_memory, reference_of, resolve_function
from .report import GroupStatus, RunReport
from .supervisor import Elsewhere, Supervisor
from .threads import ThreadRunner

if TYPE_CHECKING:
    from ..live.server import LiveView
    from ..transport.ros_lanes import RosSettings
    from .processes import ProcessRunner

__all__ = ["System"]

TRANSPORTS = ("inproc", "process", "dds")


class System:
    """A protocol and the groups that run its roles.

    Args:
        global_type: the checked global type every channel follows.
        transport: ``"inproc"`` (every role is a thread of this process),
            ``"process"`` (each group is its own OS process; its roles are threads in it)
            or ``"dds"`` (as "process", but channels between groups are DDS topics on
            Cyclone DDS, so groups may run on several hosts).
        monitors: False turns the run-time checks off (for measurements only).
        domain: ``transport="dds"``: the DDS domain id (the environment variable
            ``ANODIZE_DDS_DOMAIN`` overrides it).
        run_id: ``transport="dds"``: keeps two runs of the same system on one domain
            apart; every host of a run must use the same one.
        ros_topics: ``transport="dds"``: labels of channels published as ROS 2 topics,
            ``{"Move->Gazebo": "/cmd_vel", "Camera->VisOdom:color": "/camera/color/image_raw"}``
            (a channel with one label may leave the label out). The run then lives on the
            ROS domain (``ROS_DOMAIN_ID``, else ``ros_domain``, else 0). Other transports
            run the same system without ROS topics.
        external: ``transport="dds"``: roles that ROS 2 nodes play; anodize runs no code for
            them, and every message to or from them must be on a ROS topic.
        ros_distro: the ROS 2 distribution whose message definitions are used ("" for the
            default, Jazzy).
        ros_domain: the ROS domain when ``ROS_DOMAIN_ID`` is not set.
        capacities: ``{"Control->Move": 4}``: channels that hold at most so many messages;
            their senders wait while they are full (between threads of one process, and on
            DDS; between processes a pipe's buffer bounds a channel instead, as the report says).
    """

    def __init__(self, global_type: GlobalType, transport: str = "inproc", monitors: bool = True,
                 domain: int = 0, run_id: str = "", ros_topics: Mapping[str, str] | None = None,
                 external: Iterable[str] = (), ros_distro: str = "", ros_domain: int | None = None,
                 capacities: Mapping[str, int] | None = None) -> None:
        if transport not in TRANSPORTS:
            raise ConfigurationError(f"transport {transport!r}: expected one of {', '.join(TRANSPORTS)}")
        if isinstance(domain, bool) or not isinstance(domain, int) or not 0 <= domain <= 232:
            raise ConfigurationError(f"domain {domain!r}: expected a DDS domain id 0..232")
        self.global_type = global_type
        self.transport = transport
        self.monitors = monitors
        self.domain = domain
        self.run_id = run_id or global_type.name
        self.ros_topics = dict(ros_topics or {})
        self.external = frozenset(external)
        self.ros_distro = ros_distro
        self.ros_domain = ros_domain
        self.capacities = _capacities(global_type, capacities or {})
        unknown = sorted(self.external - set(global_type.roles))
        if unknown:
            raise ConfigurationError(f"external role {unknown[0]}: global {global_type.name} has no such role; "
                                     f"expected one of {', '.join(global_type.roles)}")
        if self.external and transport != "dds":
            raise ConfigurationError(f"external roles ({', '.join(sorted(self.external))}) are ROS 2 nodes: they need "
                                     f"transport \"dds\", not {transport!r}")
        self.groups: dict[str, Group] = {}
        self._placed: dict[str, str] = {}

    def group(self, name: str, priority: int | None = None, memory: int | str | None = None,
              cpus: set[int] | frozenset[int] | None = None, on_failure: str = FailurePolicy.STOP,
              max_restarts: int = 3, host: str | None = None) -> Group:
        """Declare a group; add its roles with ``.role(name, function)``.

        Args:
            priority: 1..99, SCHED_FIFO where permitted (else a nice value, reported).
            memory: a bound such as ``"64MiB"`` on what the group's roles allocate
                (enforced with ``transport="process"``).
            cpus: the CPUs the group may run on.
            on_failure: ``"stop"`` (the group stops, its peers get ``PeerFailedError``),
                ``"restart"`` (it starts again from its initial states, at most
                ``max_restarts`` times) or ``"stop-system"`` (every group stops).
            host: ``transport="dds"``: the host it runs on (see :meth:`run`'s ``host``).

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
        if host is not None and (not isinstance(host, str) or not host.isidentifier()):
            raise ConfigurationError(f"group {name}: host {host!r}: expected a name such as robot or base_1")
        group = Group(name, priority, parse_memory(memory), cpus or None, policy, max_restarts, host,
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
        if self.transport != "inproc":
            reference_of(function)  # another process must be able to import it
        self._placed[role] = group.name

    def run(self, timeout: float | None = None, grace: float = 2.0,
            on_status: Callable[[dict[str, GroupStatus]], None] | None = None,
            liveness: float = 2.0, host: str | None = None, wait: float = 30.0,
            record: str | os.PathLike[str] | None = None, live: LiveView | None = None) -> RunReport:
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

        With ``transport="dds"``, ``host`` runs only the groups placed on that host
        (the others are started on theirs, with the same run id and domain); None runs
        every group here. The roles start once every group has found its peers on
        the domain; a group whose peers do not all appear within ``wait`` seconds
        fails, naming the groups and hosts that never did.

        ``record`` writes every message between groups to a recording (docs/recording.md):
        an MCAP file if it ends in ``.mcap``, else a rosbag2 folder; the report's notes say
        what was recorded. With several hosts, each host records what its groups send.

        ``live`` (:func:`anodize.live.open_live_view`) serves every channel, and each group's
        status, to the Foxglove app as the run goes (docs/recording.md, "Live view in
        Foxglove"); the report's notes say what it showed and what clients published.

        Raises:
            AnodizeError: some role of the global type is in no group.
        """
        if not liveness > 0:
            raise ConfigurationError(f"liveness {liveness!r}: expected a number of seconds > 0")
        gt = self.global_type
        missing = [r for r in gt.roles if r not in self._placed and r not in self.external]
        if missing:
            raise AnodizeError(f"global {gt.name}: roles {', '.join(missing)} are in no group")
        machines = {role: gt.project(role).fsm() for role in gt.roles}
        channels = tuple(communication_graph(gt).edges)
        recording = RecordedRun(record, self._record_plan(record, machines, channels)) if record is not None else None
        shown = None
        if live is not None:
            shown = live_plan(live.socket_path, machines, dict(self._placed), self._topic_names(machines, channels))
            live.begin(shown)
            on_status = _with_live_status(on_status, live)
        runner: ProcessRunner | ThreadRunner
        if self.transport == "dds":
            report = self._run_dds(machines, channels, timeout, grace, on_status, liveness, host, wait,
                                   recording, shown)
            return _with_live(_with_recording(report, recording, gt, self.transport, self.groups), live)
        if self.transport == "process":
            from .processes import ProcessRunner

            runner = ProcessRunner(gt.name, machines, channels, self.groups, self.monitors, liveness,
                                   self.capacities)
        else:
            runner = ThreadRunner(gt, machines, channels, self.groups, self.monitors, self.capacities)
        runner.record = recording.plan if recording is not None else None
        runner.live = shown
        report = self._with_capacities(
            Supervisor(gt.name, gt.roles, self.groups, channels, runner, timeout, grace, on_status).run())
        return _with_live(_with_recording(report, recording, gt, self.transport, self.groups), live)

    def _record_plan(self, record: str | os.PathLike[str], machines: dict[str, StateMachine],
                     channels: tuple[tuple[str, str], ...]) -> RecordPlan:
        """What a recorded run records, under the system's ROS topic names where it has them."""
        parts = Path(record).with_name(f".{Path(record).name}.parts-{os.getpid()}")
        return record_plan(str(parts), machines, dict(self._placed), self._topic_names(machines, channels))

    def _topic_names(self, machines: dict[str, StateMachine],
                     channels: tuple[tuple[str, str], ...]) -> dict[tuple[str, str, str], str]:
        """``(sender, receiver, label) -> ROS topic`` of the labels the system maps to ROS topics."""
        if not self.ros_topics:
            return {}
        from ..transport.ros_lanes import ros_settings

        ros = ros_settings(machines, channels, self.ros_topics, self.external, self.ros_distro, self.ros_domain)
        return {key: topic.name for key, topic in ros.topics.items()}

    def _with_capacities(self, report: RunReport) -> RunReport:
        return dataclasses.replace(report, capacities={f"{a}->{b}": n for (a, b), n in self.capacities.items()})

    def ros_settings(self, machines: dict[str, StateMachine] | None = None,
                     channels: tuple[tuple[str, str], ...] | None = None) -> RosSettings | None:
        """The checked ROS side of the system (None without ROS topics or external roles).

        Raises:
            ConfigurationError: a topic entry or an external role that cannot be, naming it.
        """
        if not (self.ros_topics or self.external) or self.transport != "dds":
            return None
        from ..transport.ros_lanes import ros_settings

        gt = self.global_type
        machines = machines if machines is not None else {role: gt.project(role).fsm() for role in gt.roles}
        channels = channels if channels is not None else tuple(communication_graph(gt).edges)
        return ros_settings(machines, channels, self.ros_topics, self.external, self.ros_distro, self.ros_domain)

    def _run_dds(self, machines: dict[str, StateMachine], channels: tuple[tuple[str, str], ...],
                 timeout: float | None, grace: float, on_status: Callable[[dict[str, GroupStatus]], None] | None,
                 liveness: float, host: str | None, wait: float, recording: RecordedRun | None,
                 shown: LivePlan | None = None) -> RunReport:
        import_extra("cyclonedds", "dds", "the DDS transport")  # only a DDS run loads Cyclone DDS
        from ..transport.dds import DOMAIN_ENV, DdsSettings
        from .ddsrunner import DdsRunner

        if not wait > 0:
            raise ConfigurationError(f"wait {wait!r}: expected a number of seconds > 0")
        hosts = {g.host for g in self.groups.values() if g.host is not None}
        if host is not None and host not in hosts:
            raise ConfigurationError(f"no group runs on host {host!r}; the system's hosts are "
                                     f"{', '.join(sorted(hosts)) or 'none (give groups a host)'}")
        unplaced = sorted(name for name, g in self.groups.items() if g.host is None)
        if host is not None and unplaced:  # no host would run them
            raise ConfigurationError(f"--host {host}: groups {', '.join(unplaced)} have no host; give every "
                                     "group a host, or run without --host")
        here = socket.gethostname() if host is None else host
        host_of = {name: g.host or here for name, g in self.groups.items()}
        local = {name: g for name, g in self.groups.items() if host is None or g.host == host}
        domain = self.domain
        if os.environ.get(DOMAIN_ENV):
            try:
                domain = int(os.environ[DOMAIN_ENV])
                if not 0 <= domain <= 232:
                    raise ValueError
            except ValueError:
                raise ConfigurationError(f"{DOMAIN_ENV}={os.environ[DOMAIN_ENV]!r}: expected a DDS domain id") from None
        ros = self.ros_settings(machines, channels)
        if ros is not None:
            domain = ros.domain  # ROS 2 nodes meet on their domain; anodize's own topics are there too
        settings = DdsSettings(domain=domain, run_id=self.run_id, host=here,
                               group_of=dict(self._placed),
                               host_of=host_of, wait=wait, ros=ros)
        elsewhere = {name: host_of[name] for name in self.groups if name not in local}
        local_roles = [role for role in self.global_type.roles
                       if role not in self.external and self._placed[role] in local]
        local_channels = tuple((a, b) for a, b in channels if a in local_roles and b in local_roles)
        runner = DdsRunner(self.global_type.name, machines, channels, local, self.monitors, settings, elsewhere,
                           liveness, self.capacities)
        runner.record = recording.plan if recording is not None else None
        runner.live = shown
        everywhere = (Elsewhere(runner.link, dict(self.groups), channels) if runner.link is not None else None)
        return self._with_capacities(Supervisor(self.global_type.name, local_roles, local, local_channels, runner,
                                                timeout, grace, on_status, everywhere).run())


def _with_live_status(on_status: Callable[[dict[str, GroupStatus]], None] | None,
                      live: LiveView) -> Callable[[dict[str, GroupStatus]], None]:
    """``on_status`` that also publishes the statuses on the live view."""
    def both(statuses: dict[str, GroupStatus]) -> None:
        live.status(statuses)
        if on_status is not None:
            on_status(statuses)
    return both


def _with_live(report: RunReport, live: LiveView | None) -> RunReport:
    if live is None:
        return report
    return dataclasses.replace(report, notes=(*report.notes, *live.end()))


def _with_recording(report: RunReport, recording: RecordedRun | None, gt: GlobalType, transport: str,
                    groups: Mapping[str, Group]) -> RunReport:
    if recording is None:
        return report
    functions = {}
    for group in groups.values():
        for role, function in group.roles.items():
            with contextlib.suppress(AnodizeError):  # a lambda (inproc) cannot be named: replay needs it given
                functions[role] = reference_of(function)
    notes = recording.finish(gt, transport, functions)
    return dataclasses.replace(report, notes=(*report.notes, *notes))


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
