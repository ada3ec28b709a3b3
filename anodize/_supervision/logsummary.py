"""What the run's report says of the roles' logs: counts per severity, drops, the last problems."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from .._session.logs import SEVERITIES, LogEntry

__all__ = ["LogSummary", "LAST_KEPT"]

LAST_KEPT = 10  # warnings and errors the report quotes, the latest


@dataclass
class LogSummary:
    """The roles' log records over a run.

    Attributes:
        counts: per severity (DEBUG, INFO, WARN, ERROR, FATAL), the records that reached the supervisor.
        dropped: per severity, the records dropped because their group's log queue was full.
        last: the latest :data:`LAST_KEPT` records at WARN or above, oldest first.
    """

    counts: dict[str, int] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    last: deque[LogEntry] = field(default_factory=lambda: deque(maxlen=LAST_KEPT))

    def add(self, entries: Iterable[LogEntry], dropped: Mapping[str, int]) -> None:
        """Count ``entries`` and the records ``dropped`` (per severity) on their way here."""
        for entry in entries:
            name = entry.severity
            self.counts[name] = self.counts.get(name, 0) + 1
            if name in ("WARN", "ERROR", "FATAL"):
                self.last.append(entry)
        for name, n in dropped.items():
            self.dropped[name] = self.dropped.get(name, 0) + n

    @property
    def total_dropped(self) -> int:
        """Records dropped, every severity."""
        return sum(self.dropped.values())

    def lines(self) -> list[str]:
        """The report's lines (none when no role logged)."""
        if not self.counts and not self.dropped:
            return []
        counted = ", ".join(f"{self.counts[s]} {s}" for s in SEVERITIES if self.counts.get(s))
        line = f"logs: {counted or 'none delivered'}"
        if self.dropped:
            line += (f"; {self.total_dropped} dropped (" + ", ".join(
                f"{self.dropped[s]} {s}" for s in SEVERITIES if self.dropped.get(s))
                + "): a group's log queue was full, the role did not wait")
        return [line, *(f"  [{e.severity}] [{e.role}]: {e.message.splitlines()[0] if e.message else ''}"
                        for e in self.last)]

    def to_dict(self) -> dict[str, Any]:
        """Plain data: counts and drops per severity, the last warnings and errors."""
        return {"counts": {s: self.counts.get(s, 0) for s in SEVERITIES},
                "dropped": {s: self.dropped.get(s, 0) for s in SEVERITIES},
                "last": [{"severity": e.severity, "role": e.role, "group": e.group, "logger": e.logger,
                          "message": e.message, "wall": e.wall, "where": f"{e.file}:{e.line}"} for e in self.last]}
