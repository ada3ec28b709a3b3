"""What a run produced: per role, per group, per channel; and live group status."""

from __future__ import annotations

import json
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Any

from .._session.statistics import EndpointStatistics
from ..errors import AnodizeError
from .logsummary import LogSummary

if TYPE_CHECKING:
    from .._transport.ros_lanes import RosSettings

__all__ = ["RoleStatus", "GroupState", "RoleReport", "GroupReport", "RunReport", "GroupStatus", "constraint_counts"]


class RoleStatus(StrEnum):
    """How a role ended (a ``str``: ``RoleStatus.DONE == "done"``)."""

    DONE = "done"        # reached the end of its local type
    FAILED = "failed"    # raised, violated the protocol, or its group failed
    STOPPED = "stopped"  # stopped by the supervisor (timeout, interrupt, a stop-system policy)


class GroupState(StrEnum):
    """Where a group is in its life; the last three are also how it ended."""

    STARTING = "starting"
    RUNNING = "running"
    RESTARTING = "restarting"
    DONE = "done"
    FAILED = "failed"
    STOPPED = "stopped"


@dataclass(frozen=True, kw_only=True)
class RoleReport:
    """One role: ``status`` and, unless done, the ``error`` (None when stopped).

    Attributes:
        where: for a role that raised, ``file:line in function`` of the innermost
            frame in the role's own code (not anodize's), or "" when unknown.
        traceback: the last frames of the exception, innermost last, one line each.
        detail: for a stopped role, what it was doing, e.g. ``blocked in state 3
            waiting for ?Cam(Frame)``.
    """

    name: str
    group: str
    status: RoleStatus
    error: BaseException | None = None
    scheduling: str = ""
    where: str = ""
    traceback: tuple[str, ...] = ()
    detail: str = ""

    def line(self) -> str:
        """``role Sink: failed at roles.py:12 in sink: ValueError: ...`` or ``role Sink: stopped, blocked ...``."""
        text = f"role {self.name}: {self.status}"
        if self.where:
            text += f" at {self.where}"
        if self.error is not None:
            text += f": {_describe(self.error)}"
        elif self.detail:
            text += f", {self.detail}"
        return text


@dataclass(frozen=True, kw_only=True)
class GroupReport:
    """One group: failed if a role failed, else stopped if one was stopped, else done.

    Attributes:
        peak_memory: the most the group's roles had allocated, in bytes, above the
            process's baseline (interpreter and imported modules); None where not measured.
        memory_bound: the bound in bytes, or None.
        memory_note: how the bound was enforced, or why it was not.
        notes: other facts about the group (e.g. a demotion by the watchdog, samples
            rejected from a foreign DDS writer, a restart decided on another host).
        error: the group-level failure (e.g. a ``MemoryBoundError``), or None.
        restarts: how many times the group was started again (``on_failure="restart"``).
        failures: one line per failure that led to a restart or a stop, oldest first.
        messages: messages the group's roles sent.
        received: messages the group's roles received.
        rate_hz: messages sent per second, the median over the whole one-second windows
            in which every role of the group was running.
        rate_min_hz: the lowest such window (the rate the group never fell below).
        pid: the group's process, on Processes and Dds.
    """

    name: str
    status: GroupState
    scheduling: str
    peak_memory: int | None = None
    memory_note: str = ""
    memory_bound: int | None = None
    notes: tuple[str, ...] = ()
    error: BaseException | None = None
    restarts: int = 0
    failures: tuple[str, ...] = ()
    messages: int = 0
    received: int = 0
    rate_hz: float | None = None
    rate_min_hz: float | None = None
    pid: int | None = None


@dataclass(frozen=True, kw_only=True)
class GroupStatus:
    """A live snapshot of one group, handed to ``System.run(on_status=...)``.

    ``memory`` is bytes allocated above the baseline (None where not measured);
    ``messages`` and ``received`` count messages sent and received so far;
    ``rate_hz`` is messages sent per second over the last second.
    ``roles`` is each of the group's roles and where it is (the group's state until the
    role ends, then how it ended); ``sent`` and ``high_water`` are per channel ``"A->B"`` (messages
    sent so far, and the most that waited at once); ``scheduling`` is what was applied.
    """

    name: str
    state: GroupState
    pid: int | None = None
    memory: int | None = None
    messages: int = 0
    received: int = 0
    rate_hz: float | None = None
    restarts: int = 0
    note: str = ""
    roles: Mapping[str, str] = field(default_factory=dict)
    sent: Mapping[str, int] = field(default_factory=dict)
    high_water: Mapping[str, int] = field(default_factory=dict)
    scheduling: str = ""

    def line(self) -> str:
        """One line for a terminal, e.g. ``control  running  pid 4242  12.0 MiB  100 msgs  100 msg/s``."""
        parts = [f"{self.name:<12}", f"{self.state:<10}"]
        if self.pid:
            parts.append(f"pid {self.pid}")
        if self.memory is not None:
            parts.append(f"{max(0, self.memory) / 2**20:6.1f} MiB")
        parts.append(f"{self.messages} msgs")
        if self.rate_hz is not None:
            parts.append(f"{self.rate_hz:.0f} msg/s")
        if self.restarts:
            parts.append(f"{self.restarts} restarts")
        if self.note:
            parts.append(self.note)
        return "  ".join(parts)


@dataclass(frozen=True, kw_only=True)
class RunReport:
    """The supervisor's account of a run.

    Attributes:
        messages: per channel ``"A->B"``, the messages A sent to B.
        received: per channel, the messages B took from A (fewer where a run ended
            with messages in flight).
        high_water: per channel, the most messages that waited in it at once (sent, not yet
            received), where the transport can tell: channels between threads of one
            process and DDS channels (to within a credit or two); not the rings between processes,
            whose size (1 MiB) bounds them.
        capacities: per channel given a capacity, that capacity (its sender waits while
            that many messages wait).
        interrupted: the run was ended by Ctrl-C (SIGINT).
        notes: system-wide facts, e.g. the real-time guard in force.
        boosts: priority inheritance, per ``"waiter->target"`` pair of roles whose target ran
            at the waiter's priority at least once: ``{"episodes": n, "seconds": s}`` (the waits
            in which it was boosted, and the time it ran boosted).
        inheritance_inactive: roles whose group asked for a priority but did not get SCHED_FIFO
            (the fallback is a nice value): their waits lend no priority.
        constraints: per constrained interaction of a role (``"Control !Move(Twist) within
            15ms"``), ``{"checked": n, "closest_s": m}``: how often its time and value
            constraints were checked, and the closest it came to a time bound in seconds
            (negative: missed; None without a time bound), and ``"timeouts"``, how often its
            deadline passed and the receiver took ``else timeout``. A violation is the role's failure.
        lost: per channel with a ROS topic whose QoS may lose messages (best effort, keep last),
            where both ends ran here: the messages sent and not received (lost on the wire,
            overwritten in a keep-last history, or in flight at the end). The protocol allows
            it (:mod:`anodize._transport.lossy_lanes`): no violation, nobody blamed.
        logs: the roles' log records: counts per severity, those dropped, the last warnings and errors.
    """

    protocol: str
    roles: dict[str, RoleReport]
    groups: dict[str, GroupReport]
    messages: dict[str, int] = field(default_factory=dict)
    received: dict[str, int] = field(default_factory=dict)
    high_water: dict[str, int] = field(default_factory=dict)
    capacities: dict[str, int] = field(default_factory=dict)
    duration: float = 0.0
    transport: str = "inproc"
    interrupted: bool = False
    notes: tuple[str, ...] = ()
    boosts: dict[str, dict[str, float]] = field(default_factory=dict)
    inheritance_inactive: tuple[str, ...] = ()
    constraints: dict[str, dict[str, float | None]] = field(default_factory=dict)
    lost: dict[str, int] = field(default_factory=dict)
    logs: LogSummary = field(default_factory=LogSummary)

    @property
    def ok(self) -> bool:
        """Every role reached the end of its local type."""
        return all(r.status is RoleStatus.DONE for r in self.roles.values())

    @property
    def failed(self) -> bool:
        """Some role or group failed (a stop at the timeout is not a failure)."""
        return (any(r.status is RoleStatus.FAILED for r in self.roles.values())
                or any(g.status is GroupState.FAILED for g in self.groups.values()))

    @property
    def outcome(self) -> str:
        """``"ok"``, ``"NOT ok"``, ``"interrupted"`` (Ctrl-C, no failures) or
        ``"stopped, no failures"`` (a run ended by its timeout)."""
        if self.ok:
            return "ok"
        if self.failed:
            return "NOT ok"
        return "interrupted" if self.interrupted else "stopped, no failures"

    def summary(self) -> str:
        """A few lines for people: one per group, then each role that did not finish,
        with where it raised or what it was waiting for."""
        lines = [f"protocol {self.protocol}: {self.outcome} in {self.duration:.2f} s ({self.transport})"]
        for group in self.groups.values():
            lines.append(f"  group {group.name}: {group.status} ({_group_details(group)})")
            if group.error is not None:
                lines.append(f"    {type(group.error).__name__}: {group.error}")
        lines.extend(f"  {role.line()}" for role in self.roles.values() if role.status is not RoleStatus.DONE)
        if self.high_water:
            lines.append("  most messages waiting: " + ", ".join(
                f"{channel} {n}" + (f" of {self.capacities[channel]}" if channel in self.capacities else "")
                for channel, n in self.high_water.items()))
        if self.boosts:
            lines.append("  priority inheritance: " + ", ".join(
                f"{pair} {int(b['episodes'])} boosts {b['seconds'] * 1000:.1f} ms" for pair, b in self.boosts.items()))
        if self.inheritance_inactive:
            lines.append("  priority inheritance inactive for " + ", ".join(self.inheritance_inactive)
                         + " (no SCHED_FIFO: a nice value was applied instead)")
        lines.extend(f"  constraint {key}: {int(c['checked'] or 0)} checked" + _closest(c["closest_s"])
                     + (f", {int(c['timeouts'] or 0)} timeouts taken" if c.get("timeouts") else "")
                     for key, c in self.constraints.items())
        lines.extend(f"  lost {n} of {self.messages.get(channel, 0)} on {channel} (a lossy QoS; the protocol "
                     "allows it: no violation)" for channel, n in self.lost.items())
        lines.extend(f"  {line}" for line in self.logs.lines())
        lines.extend(f"  note: {note}" for note in self.notes)
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready): errors become ``{"type", "message"}``."""
        return {
            "protocol": self.protocol, "ok": self.ok, "outcome": self.outcome,
            "interrupted": self.interrupted, "duration_s": round(self.duration, 4),
            "transport": self.transport, "notes": list(self.notes), "messages": dict(self.messages),
            "received": dict(self.received), "high_water": dict(self.high_water),
            "capacities": dict(self.capacities), "lost": dict(self.lost),
            "boosts": {pair: dict(b) for pair, b in self.boosts.items()},
            "inheritance_inactive": list(self.inheritance_inactive),
            "constraints": {key: dict(c) for key, c in self.constraints.items()},
            "logs": self.logs.to_dict(),
            "groups": {name: {
                "status": str(g.status), "scheduling": g.scheduling, "peak_memory": g.peak_memory,
                "memory_bound": g.memory_bound, "memory_note": g.memory_note, "notes": list(g.notes),
                "error": _error(g.error), "restarts": g.restarts, "failures": list(g.failures),
                "messages": g.messages, "received": g.received, "rate_hz": g.rate_hz,
                "rate_min_hz": g.rate_min_hz, "pid": g.pid,
            } for name, g in self.groups.items()},
            "roles": {name: {"group": r.group, "status": str(r.status), "error": _error(r.error),
                             "where": r.where, "traceback": list(r.traceback), "detail": r.detail,
                             "scheduling": r.scheduling} for name, r in self.roles.items()},
        }

    def to_json(self) -> str:
        """:meth:`to_dict` as indented JSON."""
        return json.dumps(self.to_dict(), indent=2)


def _describe(error: BaseException) -> str:
    """Anodize's errors say what they are; others get their type named."""
    return str(error) if isinstance(error, AnodizeError) else f"{type(error).__name__}: {error}"


def _error(error: BaseException | None) -> dict[str, str] | None:
    return None if error is None else {"type": type(error).__name__, "message": str(error)}


def _group_details(group: GroupReport) -> str:
    details = [group.scheduling or "default scheduling"]
    if group.messages or group.received:
        rate = ""
        if group.rate_hz is not None and group.messages:  # a group that only receives has no send rate
            low = f", never below {group.rate_min_hz:.0f}" if group.rate_min_hz is not None else ""
            rate = f", {group.rate_hz:.0f} msg/s{low}"
        details.append(f"{group.messages} sent, {group.received} received{rate}")
    if group.peak_memory is not None:
        bound = f" of {_mib(group.memory_bound)} bound" if group.memory_bound else ""
        details.append(f"peak {_mib(group.peak_memory)}{bound}")
    if group.memory_note:
        details.append(group.memory_note)
    details.extend(group.notes)
    if group.restarts:
        details.append(f"restarted {group.restarts}x")
    return "; ".join(details)


def _mib(size: int | None) -> str:
    return f"{(size or 0) / 2**20:.1f} MiB"


def _closest(seconds: float | None) -> str:
    if seconds is None:
        return ""
    if seconds < 0:
        return f", missed by {-seconds * 1000:.1f} ms"
    return f", closest {seconds * 1000:.1f} ms inside its time bound"


def constraint_counts(statistics: Mapping[str, EndpointStatistics],
                      ) -> tuple[dict[str, int], dict[str, float], dict[str, int]]:
    """Per ``"Role interaction"``, the checks of its constraints so far, its closest margin to a
    time bound in seconds (where it has one) and the timeouts it took (where it took any): what a
    group tells the supervisor."""
    checked: dict[str, int] = {}
    closest: dict[str, float] = {}
    timeouts: dict[str, int] = {}
    for role, st in statistics.items():
        for key, check in st.constraints.items():
            checked[f"{role} {key}"] = check.checked
            if check.closest_ns is not None:
                closest[f"{role} {key}"] = check.closest_ns / 1e9
            if check.timeouts:
                timeouts[f"{role} {key}"] = check.timeouts
    return checked, closest, timeouts


def lossy_channels(ros: RosSettings | None, here: Collection[str]) -> dict[str, str]:
    """Per channel ``"A->B"`` with a ROS topic whose QoS may lose messages, both of whose roles
    run here (so the report has both counts): its lossy topics and their QoS, for the notes."""
    found: dict[str, list[str]] = {}
    if ros is None:
        return {}
    for (sender, receiver, _), topic in sorted(ros.topics.items()):
        profile = ros.qos_of(topic.name)
        if profile.lossy and sender in here and receiver in here:
            found.setdefault(f"{sender}->{receiver}", []).append(f"{topic.name} is {profile.describe()}")
    return {channel: "; ".join(topics) + " (the protocol allows a loss there: counted as lost, not a violation)"
            for channel, topics in found.items()}

