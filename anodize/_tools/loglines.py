"""The roles' log records on ``anodize run``'s terminal, as ROS 2 prints them.

One line per record, ``[INFO] [1732700000.123456] [Planner]: new plan`` (severity, wall time,
role), the way ``ros2 run`` shows a node's. Where live status lines are redrawn in place
below, they are cleared first and drawn again at their next update, so a record never lands
inside them. ``--quiet`` shows only WARN and above. The records reach here from the
supervisor's thread, after the bounded queue in each group (the roles never wait for the
terminal); a burst larger than that queue is dropped there and counted in the report.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TextIO

from .._session.logs import CAPACITY, LogEntry

__all__ = ["LogLines", "format_entry", "replayed_lines"]


def format_entry(entry: LogEntry) -> str:
    """``[SEVERITY] [wall] [role]: message`` (a message of several lines keeps them)."""
    return f"[{entry.severity}] [{entry.wall:.6f}] [{entry.role}]: {entry.message}"


class LogLines:
    """``on_log`` for ``anodize run``: writes each record at or above ``least`` (a Python level).

    Args:
        stream: where to write.
        least: the lowest level written (``logging.WARNING`` under ``--quiet``).
        clear: called before writing, to clear live lines drawn in place (they are redrawn).
    """

    def __init__(self, stream: TextIO, least: int, clear: Callable[[], None] | None = None) -> None:
        self.stream = stream
        self.least = least
        self.clear = clear

    def __call__(self, entries: Sequence[LogEntry]) -> None:
        lines = [format_entry(e) for e in entries if e.level >= self.least]
        if not lines:
            return
        if self.clear is not None:
            self.clear()
        self.stream.write("\n".join(lines) + "\n")
        self.stream.flush()


def replayed_lines(entries: Sequence[LogEntry], dropped: Mapping[str, int]) -> list[str]:
    """What ``anodize replay`` shows of the records the replayed role logged (held until it ended)."""
    lines = [format_entry(e) for e in entries]
    if dropped:
        lines.append(f"({sum(dropped.values())} more log records were dropped: past {CAPACITY} a replay keeps none)")
    return lines
