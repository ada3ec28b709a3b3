"""What a run produced: per role, per group, per channel."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

__all__ = ["RoleReport", "GroupReport", "RunReport"]

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
    """One group: failed if a role failed, else stopped if one was stopped, else done."""

    name: str
    status: Status
    scheduling: str
    peak_memory: int | None = None
    memory_note: str = ""


@dataclass(frozen=True)
class RunReport:
    """The supervisor's account of a run."""

    protocol: str
    roles: dict[str, RoleReport]
    groups: dict[str, GroupReport]
    messages: dict[str, int] = field(default_factory=dict)  # "A->B": count
    duration: float = 0.0

    @property
    def ok(self) -> bool:
        """Every role reached the end of its local type."""
        return all(r.status == "done" for r in self.roles.values())

    def summary(self) -> str:
        """A few lines for people: one per group, then each role that did not finish."""
        lines = [f"protocol {self.protocol}: {'ok' if self.ok else 'NOT ok'} in {self.duration:.2f} s"]
        for group in self.groups.values():
            memory = f", peak {group.peak_memory} bytes" if group.peak_memory else ""
            note = f"; {group.memory_note}" if group.memory_note else ""
            lines.append(f"  group {group.name}: {group.status} ({group.scheduling}{memory}{note})")
        for role in self.roles.values():
            if role.status != "done":
                lines.append(f"  role {role.name}: {role.status}" + (f": {role.error}" if role.error else ""))
        return "\n".join(lines)
