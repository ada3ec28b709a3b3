"""What a run produced: per role, per group, per channel; and live group status."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Literal

__all__ = ["RoleReport", "GroupReport", "RunReport", "GroupStatus"]

Status = Literal["done", "failed", "stopped"]


@dataclass(frozen=True)
class RoleReport:
    """One role: ``status`` and, unless done, the ``error`` (or None when stopped)."""

    name: str
    group: str
    status: Status
    error: BaseException | None = None
    scheduling: str = ""


@dataclass(frozen=True)
class GroupReport:
    """One group: failed if a role failed, else stopped if one was stopped, else done.

    Attributes:
        peak_memory: the most the group's roles had allocated, in bytes, above the
            process's baseline (interpreter and imported modules); None where not measured.
        memory_bound: the bound in bytes, or None.
        memory_note: how the bound was enforced, or why it was not.
        error: the group-level failure (e.g. a ``MemoryBoundError``), or None.
        restarts: how many times the group was started again (``on_failure="restart"``).
        failures: one line per failure that led to a restart or a stop, oldest first.
        messages: messages the group's roles sent.
        rate_hz: the median over one-second windows of messages sent per second.
        rate_min_hz: the lowest such window (the rate the group never fell below).
        pid: the group's process, for ``transport="process"``.
    """

    name: str
    status: Status
    scheduling: str
    peak_memory: int | None = None
    memory_note: str = ""
    memory_bound: int | None = None
    error: BaseException | None = None
    restarts: int = 0
    failures: tuple[str, ...] = ()
    messages: int = 0
    rate_hz: float | None = None
    rate_min_hz: float | None = None
    pid: int | None = None


@dataclass(frozen=True)
class GroupStatus:
    """A live snapshot of one group, handed to ``System.run(on_status=...)``.

    ``state`` is "starting", "running", "restarting", "done", "failed" or "stopped";
    ``memory`` is bytes allocated above the baseline (None where not measured);
    ``messages`` counts messages sent so far; ``rate_hz`` is over the last second.
    """

    name: str
    state: str
    pid: int | None = None
    memory: int | None = None
    messages: int = 0
    rate_hz: float | None = None
    restarts: int = 0
    note: str = ""

    def line(self) -> str:
        """One line for a terminal, e.g. ``control  running  pid 4242  12.0 MiB  100 msg/s``."""
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


@dataclass(frozen=True)
class RunReport:
    """The supervisor's account of a run."""

    protocol: str
    roles: dict[str, RoleReport]
    groups: dict[str, GroupReport]
    messages: dict[str, int] = field(default_factory=dict)  # "A->B": count
    duration: float = 0.0
    transport: str = "inproc"
    notes: tuple[str, ...] = ()  # system-wide facts, e.g. the real-time guard in force

    @property
    def ok(self) -> bool:
        """Every role reached the end of its local type."""
        return all(r.status == "done" for r in self.roles.values())

    @property
    def failed(self) -> bool:
        """Some role or group failed (a stop at the timeout is not a failure)."""
        return (any(r.status == "failed" for r in self.roles.values())
                or any(g.status == "failed" for g in self.groups.values()))

    @property
    def outcome(self) -> str:
        """``"ok"``, ``"stopped, no failures"`` (a run ended by its timeout) or ``"NOT ok"``."""
        if self.ok:
            return "ok"
        return "NOT ok" if self.failed else "stopped, no failures"

    def summary(self) -> str:
        """A few lines for people: one per group, then each role that failed (and, when
        some did, each role that was stopped)."""
        lines = [f"protocol {self.protocol}: {self.outcome} in {self.duration:.2f} s"
                 f" ({self.transport})"]
        for group in self.groups.values():
            lines.append(f"  group {group.name}: {group.status} ({_group_details(group)})")
            if group.error is not None:
                lines.append(f"    {type(group.error).__name__}: {group.error}")
        for role in self.roles.values():
            # A run its timeout ended stops every role: listing them all says nothing.
            if role.status == "failed" or (role.status == "stopped" and self.failed):
                lines.append(f"  role {role.name}: {role.status}" + (f": {role.error}" if role.error else ""))
        lines.extend(f"  note: {note}" for note in self.notes)
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready): errors become ``{"type", "message"}``."""
        return {
            "protocol": self.protocol, "ok": self.ok, "duration_s": round(self.duration, 4),
            "transport": self.transport, "notes": list(self.notes), "messages": dict(self.messages),
            "groups": {name: {
                "status": g.status, "scheduling": g.scheduling, "peak_memory": g.peak_memory,
                "memory_bound": g.memory_bound, "memory_note": g.memory_note,
                "error": _error(g.error), "restarts": g.restarts, "failures": list(g.failures),
                "messages": g.messages, "rate_hz": g.rate_hz, "rate_min_hz": g.rate_min_hz,
                "pid": g.pid,
            } for name, g in self.groups.items()},
            "roles": {name: {"group": r.group, "status": r.status, "error": _error(r.error),
                             "scheduling": r.scheduling} for name, r in self.roles.items()},
        }

    def to_json(self) -> str:
        """:meth:`to_dict` as indented JSON."""
        return json.dumps(self.to_dict(), indent=2)


def _error(error: BaseException | None) -> dict[str, str] | None:
    return None if error is None else {"type": type(error).__name__, "message": str(error)}


def _group_details(group: GroupReport) -> str:
    details = [group.scheduling or "default scheduling"]
    if group.rate_hz is not None and group.messages:
        low = f", never below {group.rate_min_hz:.0f}" if group.rate_min_hz is not None else ""
        details.append(f"{group.messages} msgs, {group.rate_hz:.0f} msg/s{low}")
    if group.peak_memory is not None:
        bound = f" of {_mib(group.memory_bound)} bound" if group.memory_bound else ""
        details.append(f"peak {_mib(group.peak_memory)}{bound}")
    if group.memory_note:
        details.append(group.memory_note)
    if group.restarts:
        details.append(f"restarted {group.restarts}x")
    return "; ".join(details)


def _mib(size: int | None) -> str:
    return f"{(size or 0) / 2**20:.1f} MiB"
