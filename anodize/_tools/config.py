"""System files: a protocol, a global type, a transport and the groups that run its roles.

A system file is TOML. Paths in it are relative to the file itself. It maps one to
one onto the values a Python program builds (``System(g, transport=Dds(...),
ros=RosBridge(...))``; docs/guide/transports.md)::

    include = ["base.toml"]                  # other system files this one is laid over, key by key
    protocol = "../protocols/stream.proto"   # the .proto file (required)
    global = "Pipeline"                      # the global type's name in it (required)
    timeout = 10.0                           # seconds; roles still running then are stopped
    monitors = true                          # run-time protocol checks (default true)
    pythonpath = ["."]                       # dirs prepended to sys.path (default: the file's dir)

    [transport]                              # the transport value (default: kind = "process")
    kind = "process"                         # "inproc" (Inproc), "process" (Processes), "dds" (Dds), "zenoh"
    liveness = 2.0                           # its fields: process: liveness; dds: domain, run_id,
                                             # host, wait, liveness; zenoh: run_id, host, wait, liveness,
                                             # lease, outage; inproc: none

    [zenoh]                                  # kind = "zenoh": mode, connect, listen, scouting, and
    mode = "client"                          # [zenoh.hosts.NAME] per host (see zenoh_table.py)
    connect = ["tcp/10.0.0.1:7447"]

    [ros]                                    # RosBridge: topics, external, distro, domain, namespace, remap
    topics = { "Source->Sink" = "cmd_vel" }  # relative: in its group's namespace, in the system's
    namespace = "/robot1"
    remap = { "control/cmd_vel" = "/cmd_vel" }   # after the namespaces: /robot1/control/cmd_vel -> /cmd_vel

    [params.Source]                          # System(params={"Source": {"rate": 50.0}}): keyword arguments
    rate = 50.0                              # of the role's function (bool, int, float, str, arrays of one)

    [ros.qos]                                # QoS per ROS topic (default: reliable, keep all)
    "/scan" = "sensor_data"                  # a ROS 2 profile, or { reliability = ..., depth = ... }

    [channels."A->B"]                        # capacities; qos: of the channel's ROS topics
    capacity = 8

    [record]                                 # what --record records (default: every channel)
    exclude = ["Gazebo->Camera"]             # all but these; or channels = [...]: only these

    [groups.control]                         # one table per group (at least one)
    priority = 90                            # 1..99: SCHED_FIFO
    # nice = -10                             # instead of a priority: ordinary scheduling at this nice
    memory = "64MiB"                         # a bound: bytes, or a size such as "512KiB", "1GB"
    cpus = [0]                               # the CPUs the group may run on
    on_failure = "stop"                      # "stop" (default), "restart" or "stop-system"
    max_restarts = 3                         # with on_failure = "restart" (default 3)
    host = "robot"                           # kind = "dds" or "zenoh": the host it runs on
    priority_inheritance = true              # roles waiting on this group lend it their priority (default)
    roles = { Source = "memory_hog:source", Sink = "memory_hog:sink" }   # role -> "module:function"
    namespace = "control"                    # its roles' relative topics: /robot1/control/...
    spin = "50us"                            # a receiver polls up to this long before it sleeps (default off)

Only ``protocol``, ``global``, ``groups`` and each group's ``roles`` are required.
Files of the earlier form (``transport = "dds"`` as a string, with ``domain`` and
``run_id`` at the top level) are still read, as the same values.
:func:`load_config` reads and checks a file without importing anything;
:func:`build_system` loads the protocol, imports the role functions and returns
an :class:`anodize.System` ready to ``run``.
"""

from __future__ import annotations

import os
import re
import sys
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import sessiontypes
from sessiontypes.graph import communication_graph

from .._recording.selection import RecordSelection, SelectionError, selection_from_table
from .._supervision.group import FailurePolicy, parse_memory
from .._supervision.params import ParamValue, check_value
from .._supervision.rosbridge import RosBridge
from .._supervision.rosnames import check_namespace, check_relative_name, resolve_name
from .._supervision.system import System
from .._supervision.transports import KINDS, Dds, Transport, Zenoh
from .._transport.qos_profiles import QosError, QosProfile, qos_profile
from .._transport.spin import parse_spin
from ..errors import AnodizeError, ConfigurationError, ParameterError
from .config_error import COMMAND_LINE, ConfigError
from .includes import SystemData, read_system_data
from .overrides import parse_param, parse_remap
from .zenoh_table import ZENOH_KEYS, read_zenoh_table

__all__ = ["ConfigError", "GroupConfig", "SystemConfig", "load_config", "build_system",
           "add_pythonpath"]

_TOP_KEYS = ("protocol", "global", "transport", "timeout", "monitors", "pythonpath", "groups", "domain", "run_id",
             "ros", "channels", "record", "params", "include", "zenoh")
_CHANNEL_KEYS = ("capacity", "qos")
_ROS_KEYS = ("topics", "external", "distro", "domain", "qos", "namespace", "remap")
_OLD_DDS_KEYS = ("domain", "run_id")  # top-level keys of the earlier form, now fields of [transport]
_RUN_ID = re.compile(r"[A-Za-z0-9_.-]{1,64}")
_GROUP_KEYS = ("priority", "memory", "cpus", "on_failure", "max_restarts", "roles", "host",
               "priority_inheritance", "nice", "namespace", "spin")
_REFERENCE = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(\.[A-Za-z_]\w*)*")


@dataclass(frozen=True)
class GroupConfig:
    """One ``[groups.NAME]`` table.

    Attributes:
        name: the group's name.
        priority: 1..99, or None.
        memory: the memory bound in bytes, or None.
        cpus: the CPUs the group may use, sorted, or None.
        on_failure: ``"stop"``, ``"restart"`` or ``"stop-system"``.
        max_restarts: how often ``on_failure = "restart"`` restarts the group.
        roles: role name -> ``"module:function"``, in file order.
        location: where the group is written, for messages: ``"path: groups.NAME"``.
        host: ``transport = "dds"``: the host the group runs on, or None.
        priority_inheritance: whether a higher-priority role waiting on this group's roles
            raises their priority while it waits (default True).
        nice: with no priority, the group's nice value under ordinary scheduling, or None.
        namespace: the ROS namespace of the group's topics ("": the system's).
        spin: nanoseconds a receiver of the group may poll before it sleeps (0: never).
    """

    name: str
    priority: int | None
    memory: int | None
    cpus: tuple[int, ...] | None
    on_failure: str
    max_restarts: int
    roles: dict[str, str]
    location: str
    host: str | None = None
    priority_inheritance: bool = True
    nice: int | None = None
    namespace: str = ""
    spin: int = 0


@dataclass(frozen=True)
class SystemConfig:
    """A checked system file.

    Attributes:
        path: the system file, as given.
        protocol: the ``.proto`` file (relative paths are taken from the system file's dir).
        global_name: the global type's name.
        transport: the transport value (``[transport]``, or the earlier ``transport = "..."``).
        timeout: seconds after which running roles are stopped, or None.
        monitors: whether endpoints check the protocol at run time.
        pythonpath: absolute dirs to put in front of ``sys.path``.
        groups: group name -> its configuration, in file order.
        ros: ``[ros]``: the ROS 2 bridge (topics, external roles, distro, domain), or None.
        capacities: ``[channels."A->B"] capacity``: channels that hold at most so many messages.
        record: ``[record]``: the channels ``--record`` records (default: every one).
        params: ``[params.Role]``: role -> its parameters (``System(params=...)``).
        zenoh: ``[zenoh]``: the fields of :class:`~anodize.Zenoh` it gives (also for ``--transport zenoh``).
        given_on_command_line: the ``(role, parameter)`` pairs ``-p`` gave (for messages).
        remapped_on_command_line: the sources of the remaps ``-r`` gave (for messages).
        origins: dotted key -> the included file that gave its value (for messages about
            what is found when the system is built, :meth:`origin`).
    """

    path: Path
    protocol: Path
    global_name: str
    transport: Transport
    timeout: float | None
    monitors: bool
    pythonpath: tuple[Path, ...]
    groups: dict[str, GroupConfig]
    ros: RosBridge | None = None
    capacities: dict[str, int] = field(default_factory=dict)
    record: RecordSelection = field(default_factory=RecordSelection)
    params: dict[str, dict[str, ParamValue]] = field(default_factory=dict)
    zenoh: dict[str, Any] = field(default_factory=dict)
    given_on_command_line: frozenset[tuple[str, str]] = frozenset()
    remapped_on_command_line: frozenset[str] = frozenset()
    origins: dict[str, str] = field(default_factory=dict, compare=False)

    def origin(self, key: str | None) -> str:
        """The file that wrote ``key`` (or its nearest enclosing table): an included one, else this."""
        return SystemData({}, self.origins).origin(key, str(self.path))

    @property
    def external(self) -> frozenset[str]:
        """The roles ROS 2 nodes play (``[ros] external``)."""
        return self.ros.external if self.ros is not None else frozenset()

    def group_of(self, role: str) -> str | None:
        """The group that runs ``role``, or None."""
        return next((g.name for g in self.groups.values() if role in g.roles), None)

    def with_overrides(self, params: Sequence[str] = (), remaps: Sequence[str] = (),
                           namespace: str | None = None) -> SystemConfig:
        """The system with what the command line gives laid over it (``anodize run FILE -p ... -r ...``).

        Args:
            params: ``"Role.name=value"`` each (``-p``), the value in TOML; later ones win.
            remaps: ``"from:=to"`` each (``-r``), added to ``[ros.remap]`` (the same source: the command line's).
            namespace: the system's ROS namespace (``--namespace``), instead of ``[ros] namespace``.

        Raises:
            ConfigError: at ``command line`` (:attr:`ConfigError.on_command_line`): a malformed
                override, a role in no group, a namespace or remap that is not a ROS name.
        """
        values = {role: dict(given) for role, given in self.params.items()}
        given_here: set[tuple[str, str]] = set(self.given_on_command_line)
        for text in params:
            role, name, value = parse_param(text)
            if self.group_of(role) is None:
                placed = [r for group in self.groups.values() for r in group.roles]
                raise ConfigError(COMMAND_LINE, f"-p {role}.{name}", f"no role {role} runs in a group of {self.path}; "
                                                                     f"expected one of {', '.join(placed)}")
            try:
                values.setdefault(role, {})[name] = check_value(role, name, value)
            except ParameterError as error:
                raise ConfigError(COMMAND_LINE, f"-p {role}.{name}", error.problem) from None
            given_here.add((role, name))
        ros = self.ros
        if remaps or namespace is not None:
            ros = ros or RosBridge()
            remap = dict(ros.remap)
            for text in remaps:
                source, target = parse_remap(text)
                problem = check_relative_name(source) or check_relative_name(target)
                if problem is not None:
                    raise ConfigError(COMMAND_LINE, f"-r {text}", problem)
                remap[source] = target
            if namespace is not None and check_namespace(namespace) is not None:
                raise ConfigError(COMMAND_LINE, f"--namespace {namespace}", f"{check_namespace(namespace)}")
            ros = replace(ros, remap=remap, namespace=ros.namespace if namespace is None else namespace)
        return replace(self, params=values, given_on_command_line=frozenset(given_here), ros=ros,
                       remapped_on_command_line=self.remapped_on_command_line | {parse_remap(r)[0] for r in remaps})

    def on_transport(self, kind: str) -> SystemConfig:
        """The same system on the transport ``kind`` (``anodize run --transport``): the file's
        transport fields that ``kind`` also has are kept, the others take their defaults.

        Raises:
            ConfigError: not a transport kind.
        """
        if kind not in KINDS:
            raise ConfigError(str(self.path), "transport", f"expected one of {', '.join(map(_show, KINDS))}, "
                                                           f"got {_show(kind)}")
        if kind == self.transport.kind:
            return self
        kept = {f.name: getattr(self.transport, f.name) for f in fields(self.transport)}
        if kind == "zenoh":
            kept.update(self.zenoh)
        cls = KINDS[kind]
        try:
            return replace(self, transport=cls(**{f.name: kept[f.name] for f in fields(cls) if f.name in kept}))
        except ConfigurationError as error:
            raise ConfigError(str(self.path), "zenoh", str(error)) from None


def load_config(path: str | Path) -> SystemConfig:
    """Read and check a system file; nothing is imported or loaded yet.

    Raises:
        ConfigError: the file cannot be read, is not TOML (``path:line:col: ...``),
            has an unknown or missing key, or a value of the wrong type or range
            (``path: key: expected ..., got ...``).
    """
    path = Path(path)
    shown = str(path)
    read = read_system_data(path, shown)
    return _Reader(shown, path, read).system(read.data)


class _Reader:
    """Checks the parsed TOML of one file, key by key."""

    def __init__(self, shown: str, path: Path, read: SystemData) -> None:
        self.shown = shown
        self.directory = path.parent
        self.read = read

    def error(self, key: str | None, problem: str) -> ConfigError:
        return ConfigError(self.read.origin(key, self.shown), key, problem)

    def system(self, data: dict[str, Any]) -> SystemConfig:
        self.known_keys(data, _TOP_KEYS, None)
        protocol = self.required_string(data, "protocol")
        global_name = self.required_string(data, "global")
        timeout = data.get("timeout")
        if timeout is not None and not _is_seconds(timeout):
            raise self.error("timeout", f"expected a number of seconds > 0, got {_show(timeout)}")
        monitors = data.get("monitors", True)
        if not isinstance(monitors, bool):
            raise self.error("monitors", f"expected true or false, got {_show(monitors)}")
        zenoh = read_zenoh_table(data.get("zenoh"), self.error, self.directory)
        return SystemConfig(
            path=Path(self.shown), protocol=Path(os.path.normpath(self.directory / protocol)),
            global_name=global_name, transport=self.transport(data, zenoh), zenoh=zenoh,
            timeout=None if timeout is None else float(timeout), monitors=monitors,
            pythonpath=self.pythonpath(data.get("pythonpath", ["."])),
            groups=self.groups(data.get("groups")), ros=self.ros(data.get("ros"), data.get("channels")),
            capacities=self.capacities(data.get("channels", {})), record=self.record(data.get("record")),
            params=self.params(data.get("params", {})), origins=dict(self.read.origins))

    def record(self, table: Any) -> RecordSelection:
        """``[record]``: its shape here; its channels against the protocol when the system is built."""
        try:
            return selection_from_table(table)
        except SelectionError as error:
            raise self.error(f"record.{error.key}".rstrip("."), error.problem) from None

    def params(self, table: Any) -> dict[str, dict[str, ParamValue]]:
        """``[params.Role]`` tables: the values' types here; the roles and their functions when built."""
        if not isinstance(table, dict):
            raise self.error("params", f"expected tables such as [params.Planner], got {_show(table)}")
        found: dict[str, dict[str, ParamValue]] = {}
        for role, values in table.items():
            if not isinstance(values, dict):
                raise self.error(f"params.{role}", f"expected a table such as {{ speed = 0.3 }}, got {_show(values)}")
            found[role] = {}
            for name, value in values.items():
                try:
                    found[role][name] = check_value(role, name, value)
                except ParameterError as error:
                    raise self.error(f"params.{role}.{name}", error.problem) from None
        return found

    def transport(self, data: dict[str, Any], zenoh: dict[str, Any]) -> Transport:
        """``[transport]`` (kind and fields), or the earlier form: ``transport = "kind"`` with
        ``domain`` and ``run_id`` at the top level; on kind zenoh, with what ``[zenoh]`` gives."""
        given = data.get("transport", "process")
        if isinstance(given, dict):
            stray = [key for key in _OLD_DDS_KEYS if key in data]
            if stray:
                raise self.error(stray[0], f"with a [transport] table, {stray[0]} is one of its keys: "
                                           f"write transport.{stray[0]} (in [transport])")
            kind = given.get("kind")
            if not isinstance(kind, str) or kind not in KINDS:
                raise self.error("transport.kind", f"expected {' or '.join(map(_show, KINDS))}, got "
                                                   f"{_show(kind) if 'kind' in given else 'nothing (it is required)'}")
            table, prefix = {k: v for k, v in given.items() if k != "kind"}, "transport"
            allowed = tuple(f.name for f in fields(KINDS[kind]) if kind != "zenoh" or f.name not in ZENOH_KEYS)
            for key in table:
                if kind == "zenoh" and key in ZENOH_KEYS:
                    raise self.error(f"transport.{key}", f"{key} is a key of [zenoh]: write zenoh.{key} (in [zenoh])")
                if key not in allowed:
                    raise self.error(f"transport.{key}", f"unknown key for kind = {_show(kind)}; expected "
                                     f"{'one of ' + ', '.join(sorted(('kind', *allowed)))}")
        elif isinstance(given, str) and given in KINDS:
            kind, prefix = given, None  # the earlier form: its DDS keys are at the top level, checked on any kind
            table = {key: data[key] for key in _OLD_DDS_KEYS if key in data}
        else:
            raise self.error("transport", f"expected {' or '.join(map(_show, KINDS))}, or a table [transport] "
                                          f"with kind = ..., got {_show(given)}")
        checked = {key: self.transport_field(key, value, prefix) for key, value in table.items()}
        if kind == "zenoh":
            if zenoh.get("mode") == "client" and not zenoh.get("connect"):
                raise self.error("zenoh.connect", 'mode "client": expected the endpoints of one or more routers, '
                                                  "got none")
            try:
                return Zenoh(**checked, **zenoh)
            except ConfigurationError as error:  # one about TLS points at [zenoh.tls] or [zenoh]
                key = ("zenoh.tls" if " tls: " in str(error) else "zenoh" if "with tls" in str(error)
                       else prefix or "transport")
                raise self.error(key, str(error)) from None
        if kind != "dds":
            return KINDS[kind](**{k: v for k, v in checked.items() if k not in _OLD_DDS_KEYS})
        try:
            return Dds(**checked)
        except ConfigurationError as error:
            raise self.error(prefix or "transport", str(error)) from None

    def transport_field(self, key: str, value: Any, prefix: str | None) -> Any:
        """One field of a transport, checked and converted (seconds become floats)."""
        dotted = f"{prefix}.{key}" if prefix else key
        if key == "domain" and (not _is_int(value) or not 0 <= value <= 232):
            raise self.error(dotted, f"expected a DDS domain id 0..232, got {_show(value)}")
        if key == "run_id" and (not isinstance(value, str) or not _RUN_ID.fullmatch(value)):
            raise self.error(dotted, f"expected up to 64 letters, digits, '_', '.' or '-', got {_show(value)}")
        if key == "host" and (not isinstance(value, str) or not value.isidentifier()):
            raise self.error(dotted, f"expected a name such as \"robot\", got {_show(value)}")
        if key in ("wait", "liveness", "lease"):
            if not _is_seconds(value):
                raise self.error(dotted, f"expected a number of seconds > 0, got {_show(value)}")
            return float(value)
        if key == "outage":
            if not (_is_seconds(value) or value == 0) or isinstance(value, bool):
                raise self.error(dotted, f"expected a number of seconds >= 0, got {_show(value)}")
            return float(value)
        return value

    def capacities(self, table: Any) -> dict[str, int]:
        """``[channels."A->B"] capacity = n``: the shape here; the channels when the system is built."""
        if not isinstance(table, dict):
            raise self.error("channels", f'expected tables such as [channels."A->B"], got {_show(table)}')
        found: dict[str, int] = {}
        for channel, settings in table.items():
            key = f"channels.{channel}"
            if not isinstance(settings, dict):
                raise self.error(key, f"expected a table such as {{ capacity = 8 }}, got {_show(settings)}")
            self.known_keys(settings, _CHANNEL_KEYS, key)
            if "qos" in settings and "capacity" not in settings:
                continue  # a QoS alone: read with [ros] (self.ros)
            capacity: Any = settings.get("capacity")
            if not _is_int(capacity) or capacity < 1:
                raise self.error(f"{key}.capacity", f"expected a whole number of messages >= 1, got {_show(capacity)}")
            found[channel] = capacity
        return found

    def ros(self, table: Any, channels: Any = None) -> RosBridge | None:
        """The ``[ros]`` table (with the ``qos`` of ``[channels."A->B"]``): what is checked here is its
        shape; the topics against the protocol are checked when the system is built."""
        channel_qos = self.channel_qos(channels)
        if table is None:
            if channel_qos:
                raise self.error(f'channels."{next(iter(channel_qos))}".qos', "a QoS is a ROS topic's, and this "
                                 "system has no [ros.topics]; anodize's own topics stay reliable and keep-all")
            return None
        if not isinstance(table, dict):
            raise self.error("ros", f"expected a table [ros], got {_show(table)}")
        self.known_keys(table, _ROS_KEYS, "ros")
        topics = table.get("topics", {})
        if not isinstance(topics, dict) or not all(isinstance(v, str) for v in topics.values()):
            raise self.error("ros.topics", 'expected a table such as { "Move->Gazebo" = "/cmd_vel" }, '
                                           f"got {_show(topics)}")
        external = table.get("external", [])
        if not isinstance(external, list) or not all(isinstance(r, str) and r for r in external):
            raise self.error("ros.external", f'expected an array of role names such as ["Joy"], got {_show(external)}')
        distro = table.get("distro", "")
        if not isinstance(distro, str):
            raise self.error("ros.distro", f'expected a ROS 2 distribution such as "jazzy", got {_show(distro)}')
        domain = table.get("domain")
        if domain is not None and (not _is_int(domain) or not 0 <= domain <= 232):
            raise self.error("ros.domain", f"expected a DDS domain id 0..232, got {_show(domain)}")
        namespace = table.get("namespace", "")
        problem = check_namespace(namespace)
        if problem is not None:
            raise self.error("ros.namespace", f"{problem}, got {_show(namespace)}")
        remap = table.get("remap", {})
        if not isinstance(remap, dict):
            raise self.error("ros.remap", 'expected a table such as { "/cmd_vel" = "/r1/cmd_vel" }, '
                                          f"got {_show(remap)}")
        for source, target in remap.items():
            problem = check_relative_name(source) or check_relative_name(target)
            if problem is not None:
                raise self.error(f"ros.remap.{source}", f"{problem}, got {_show(source)} = {_show(target)}")
        for key, name in topics.items():
            problem = check_relative_name(name)
            if problem is not None:
                raise self.error(f"ros.topics.{key}", f"{problem}, got {_show(name)}")
        qos = table.get("qos", {})
        if not isinstance(qos, dict):
            raise self.error("ros.qos", f'expected a table such as {{ "/scan" = "sensor_data" }}, got {_show(qos)}')
        profiles = {**channel_qos, **{topic: self.qos(value, f'ros.qos."{topic}"') for topic, value in qos.items()}}
        return RosBridge(topics=dict(topics), external=frozenset(external), distro=distro, domain=domain,
                         qos=profiles, namespace=namespace, remap=dict(remap))

    def channel_qos(self, channels: Any) -> dict[str, QosProfile]:
        """``[channels."A->B"] qos``, per channel (the shape of ``[channels]`` is checked by capacities)."""
        if not isinstance(channels, dict):
            return {}
        return {channel: self.qos(settings["qos"], f'channels."{channel}".qos') for channel, settings
                in channels.items() if isinstance(settings, dict) and "qos" in settings}

    def qos(self, value: Any, key: str) -> QosProfile:
        try:
            return qos_profile(value, key)
        except QosError as error:
            raise self.error(error.key, error.problem) from None

    def known_keys(self, table: dict[str, Any], allowed: tuple[str, ...], prefix: str | None) -> None:
        for key in table:
            if key not in allowed:
                dotted = f"{prefix}.{key}" if prefix else key
                raise self.error(dotted, f"unknown key; expected one of {', '.join(sorted(allowed))}")

    def required_string(self, table: dict[str, Any], key: str) -> str:
        value = self.string(table, key)
        if value is None:
            raise self.error(key, "missing (it is required)")
        return value

    def string(self, table: dict[str, Any], key: str) -> str | None:
        if key not in table:
            return None
        value = table[key]
        if not isinstance(value, str) or not value:
            raise self.error(key, f"expected a non-empty string, got {_show(value)}")
        return value

    def pythonpath(self, value: Any) -> tuple[Path, ...]:
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise self.error("pythonpath", f"expected an array of directories, got {_show(value)}")
        return tuple(Path(os.path.abspath(self.directory / entry)) for entry in value)

    def groups(self, value: Any) -> dict[str, GroupConfig]:
        if value is None:
            raise self.error("groups", "missing (it is required): add a table such as [groups.main]")
        if not isinstance(value, dict):
            raise self.error("groups", f"expected tables such as [groups.main], got {_show(value)}")
        if not value:
            raise self.error("groups", "expected at least one group, such as [groups.main]")
        groups: dict[str, GroupConfig] = {}
        placed: dict[str, str] = {}
        for name, table in value.items():
            group = self.group(name, table)
            for role in group.roles:
                if role in placed:
                    raise self.error(f"groups.{name}.roles.{role}",
                                     f"role {role} is already in group {placed[role]}")
                placed[role] = name
            groups[name] = group
        return groups

    def group(self, name: str, table: Any) -> GroupConfig:
        prefix = f"groups.{name}"
        if not isinstance(table, dict):
            raise self.error(prefix, f"expected a table, got {_show(table)}")
        self.known_keys(table, _GROUP_KEYS, prefix)
        priority = table.get("priority")
        if priority is not None and (not _is_int(priority) or not 1 <= priority <= 99):
            raise self.error(f"{prefix}.priority", f"expected an int 1..99, got {_show(priority)}")
        memory = table.get("memory")
        try:
            memory_bytes = parse_memory(memory)
        except ConfigurationError:
            raise self.error(f"{prefix}.memory", "expected a size such as \"64MiB\", \"512KiB\" or a "
                                                 f"number of bytes, at most 8 EiB, got {_show(memory)}") from None
        on_failure = table.get("on_failure", "stop")
        if not isinstance(on_failure, str) or on_failure not in {p.value for p in FailurePolicy}:
            raise self.error(f"{prefix}.on_failure", f"expected one of "
                             f"{', '.join(_show(p.value) for p in FailurePolicy)}, got {_show(on_failure)}")
        max_restarts = table.get("max_restarts", 3)
        if not _is_int(max_restarts) or max_restarts < 0:
            raise self.error(f"{prefix}.max_restarts", f"expected an int >= 0, got {_show(max_restarts)}")
        host = table.get("host")
        if host is not None and (not isinstance(host, str) or not host.isidentifier()):
            raise self.error(f"{prefix}.host", f"expected a name such as \"robot\", got {_show(host)}")
        inherit = table.get("priority_inheritance", True)
        if not isinstance(inherit, bool):
            raise self.error(f"{prefix}.priority_inheritance", f"expected true or false, got {_show(inherit)}")
        nice = table.get("nice")
        if nice is not None and (not _is_int(nice) or not -20 <= nice <= 19):
            raise self.error(f"{prefix}.nice", f"expected an int -20..19, got {_show(nice)}")
        if nice is not None and priority is not None:
            raise self.error(f"{prefix}.nice", f"priority {priority} (SCHED_FIFO) and nice {nice} (ordinary "
                                               "scheduling) exclude each other: give one")
        namespace = table.get("namespace", "")
        problem = check_namespace(namespace)
        if problem is not None:
            raise self.error(f"{prefix}.namespace", f"{problem}, got {_show(namespace)}")
        spin = table.get("spin")
        try:
            spin_nanos = parse_spin(spin)
        except ConfigurationError:
            raise self.error(f"{prefix}.spin", "expected a duration such as \"50us\" or \"0.2ms\" (at most "
                                               f"\"1ms\"), or an int of microseconds, got {_show(spin)}") from None
        return GroupConfig(name, priority, memory_bytes, self.cpus(prefix, table.get("cpus")),
                           on_failure, max_restarts, self.roles(prefix, table),
                           f"{self.read.origin(prefix, self.shown)}: {prefix}", host, inherit, nice, namespace,
                           spin_nanos)

    def cpus(self, prefix: str, value: Any) -> tuple[int, ...] | None:
        if value is None:
            return None
        if (not isinstance(value, list) or not value
                or not all(_is_int(cpu) and cpu >= 0 for cpu in value)):
            raise self.error(f"{prefix}.cpus", "expected a non-empty array of CPU numbers, "
                                               f"got {_show(value)}")
        return tuple(sorted(set(value)))

    def roles(self, prefix: str, table: dict[str, Any]) -> dict[str, str]:
        if "roles" not in table:
            raise self.error(f"{prefix}.roles", "missing (it is required): "
                             'roles = { Role = "module:function" }')
        roles = table["roles"]
        if not isinstance(roles, dict) or not roles:
            raise self.error(f"{prefix}.roles", 'expected a table such as { Role = "module:function" }, '
                                                f"got {_show(roles)}")
        for role, reference in roles.items():
            if not isinstance(reference, str) or not _REFERENCE.fullmatch(reference):
                raise self.error(f"{prefix}.roles.{role}",
                                 f'expected "module:function", got {_show(reference)}')
        return dict(roles)


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_seconds(value: Any) -> bool:
    """A number > 0 that a wait can take (TOML has ``inf``, ``nan`` and 20-digit integers;
    none is a timeout: a wait longer than ``threading.TIMEOUT_MAX`` raises OverflowError)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    return 0 < value <= threading.TIMEOUT_MAX  # False for nan


def _show(value: Any) -> str:
    """A value as TOML would spell it, for 'got ...' in messages."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        if len(value) > 60:  # a mistake thousands of characters long need not be repeated whole
            return f"{_show(value[:24])[:-1]}...{_show(value[-24:])[1:]} ({len(value)} characters)"
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, list):
        if len(value) > 8:  # as for strings: a few items and the count, not ten thousand
            return "[" + ", ".join(_show(v) for v in value[:3]) + f", ... ({len(value)} items)]"
        return "[" + ", ".join(_show(v) for v in value) + "]"
    if isinstance(value, dict):
        return "a table"
    return f"a {type(value).__name__}"  # dates and times


def add_pythonpath(config: SystemConfig) -> None:
    """Put the config's ``pythonpath`` in front of ``sys.path`` (once, in order)."""
    for directory in reversed(config.pythonpath):
        entry = str(directory)
        if entry not in sys.path:
            sys.path.insert(0, entry)


def build_system(config: SystemConfig) -> System:
    """Load the protocol, import the role functions and declare the groups.

    Raises:
        sessiontypes.ProtocolError: the protocol file has errors.
        ConfigError: the protocol file cannot be read, has no such global, a group
            or role is refused (``path: groups.NAME: ...``), or a role of the global
            type is in no group.
    """
    shown = str(config.path)
    try:
        module = sessiontypes.load(str(config.protocol))
    except OSError as error:
        raise ConfigError(shown, "protocol", f"cannot read {config.protocol}: "
                                             f"{error.strerror or error}") from None
    if config.global_name not in module.globals:
        raise ConfigError(shown, "global", f"no global {config.global_name} in {config.protocol}; "
                                           f"expected one of {', '.join(module.globals) or '(none)'}")
    global_type = module.globals[config.global_name]
    add_pythonpath(config)
    try:
        system = System(global_type, transport=config.transport, monitors=config.monitors, ros=config.ros,
                        capacities=config.capacities, params=config.params)
    except ParameterError as error:
        raise _parameter_error(config, error) from None
    except ConfigurationError as error:
        key = "channels" if str(error).startswith("capacity of") else "ros"
        raise ConfigError(config.origin(key), key, str(error)) from None
    try:
        config.record.check(communication_graph(global_type).edges, f"global {global_type.name}")
    except SelectionError as error:
        raise ConfigError(config.origin("record"), f"record.{error.key}", error.problem) from None
    for group in config.groups.values():
        try:
            declared = system.group(group.name, priority=group.priority, memory=group.memory,
                                    cpus=set(group.cpus) if group.cpus else None,
                                    on_failure=group.on_failure, max_restarts=group.max_restarts,
                                    host=group.host, priority_inheritance=group.priority_inheritance,
                                    nice=group.nice, namespace=group.namespace,
                                    spin=f"{group.spin}ns" if group.spin else None)
            for role, reference in group.roles.items():
                declared.role(role, reference)
        except (ValueError, AnodizeError) as error:
            raise ConfigError(config.origin(f"groups.{group.name}"), f"groups.{group.name}", str(error)) from None
    missing = [role for role in global_type.roles if config.group_of(role) is None and role not in config.external]
    if missing:
        raise ConfigError(shown, "groups", f"{'role' if len(missing) == 1 else 'roles'} "
                                           f"{', '.join(missing)} of global {global_type.name} "
                                           f"{'is' if len(missing) == 1 else 'are'} in no group")
    try:
        system.check_params()
    except ParameterError as error:
        raise _parameter_error(config, error) from None
    try:
        # The topics against the protocol, now rather than when the run starts; on Dds that checks
        # the QoS too, on another transport the QoS is checked alone (for `run --transport dds`).
        bridge = system.resolved_ros()
        if system.ros_settings() is None and bridge is not None and bridge.qos:
            bridge.settings({role: global_type.project(role).fsm() for role in global_type.roles},
                            tuple(communication_graph(global_type).edges))
    except QosError as error:
        raise ConfigError(config.origin(_dotted(error.key)), error.key, error.problem) from None
    except ConfigurationError as error:
        source = str(error).partition(":")[0].removeprefix("remap ")
        namespace = config.ros.namespace if config.ros is not None else ""
        given = {resolve_name(name, namespace): name for name in config.remapped_on_command_line}  # as resolved
        if source in given:
            raise ConfigError(COMMAND_LINE, f"-r {given[source]}", str(error).partition(": ")[2]) from None
        raise ConfigError(config.origin("ros"), "ros", str(error)) from None
    return system


def _dotted(key: str) -> str:
    """A QoS error's key (``ros.qos."/scan"``, ``channels."A->B".qos``) as the reader's dotted origins name it."""
    return key.replace('"', "")


def _parameter_error(config: SystemConfig, error: ParameterError) -> ConfigError:
    """A refused parameter, located where it was given: ``-p Role.name`` or ``[params.Role] name``."""
    if (error.role, error.parameter) in config.given_on_command_line:
        return ConfigError(COMMAND_LINE, f"-p {error.role}.{error.parameter}", error.problem)
    key = f"params.{error.role}.{error.parameter}" if error.parameter else f"params.{error.role}"
    return ConfigError(config.origin(key), key, error.problem)
