"""The roles' log records in the live view: Foxglove's ``foxglove.Log`` on ``/rosout``.

Foxglove's Log panel shows any topic of schema ``foxglove.Log``; the live view publishes
the records there as JSON (the schema's JSON form, :data:`LOG_SCHEMA`), so no protobuf is
needed on either side. Records wait for the view's publishing thread in a bounded queue
(:class:`LogQueue`): the supervisor, which hands them over, never waits for a client, and
when a burst overflows it the oldest are dropped and counted.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Sequence
from typing import Any

from .._session.logs import LogEntry

__all__ = ["LOG_TOPIC", "LOG_SCHEMA_NAME", "LOG_SCHEMA", "FOXGLOVE_LEVELS", "LogQueue", "foxglove_log"]

LOG_TOPIC = "/rosout"
LOG_SCHEMA_NAME = "foxglove.Log"
FOXGLOVE_LEVELS = {"DEBUG": 1, "INFO": 2, "WARN": 3, "ERROR": 4, "FATAL": 5}  # foxglove.LogLevel
LOG_SCHEMA: dict[str, Any] = {
    "title": "foxglove.Log", "description": "A log message", "type": "object",
    "properties": {
        "timestamp": {"type": "object", "title": "time", "properties": {
            "sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}},
        "level": {"title": "foxglove.LogLevel", "type": "integer",
                  "oneOf": [{"title": n, "const": v} for n, v in
                            (("UNKNOWN", 0), ("DEBUG", 1), ("INFO", 2), ("WARNING", 3), ("ERROR", 4), ("FATAL", 5))]},
        "message": {"type": "string"}, "name": {"type": "string"}, "file": {"type": "string"},
        "line": {"type": "integer", "minimum": 0},
    },
}
QUEUE = 4096  # records waiting for the publishing thread, at most


def foxglove_log(entry: LogEntry) -> dict[str, Any]:
    """``entry`` as a JSON ``foxglove.Log``: its name is the role's."""
    seconds = int(entry.wall // 1)
    return {"timestamp": {"sec": seconds, "nsec": min(999_999_999, int((entry.wall - seconds) * 1e9))},
            "level": FOXGLOVE_LEVELS[entry.severity], "message": entry.message, "name": entry.role,
            "file": entry.file, "line": max(0, entry.line)}


class LogQueue:
    """Records waiting to be published: :meth:`put` never waits; past :data:`QUEUE` the oldest go."""

    def __init__(self, capacity: int = QUEUE) -> None:
        self._entries: deque[LogEntry] = deque(maxlen=capacity)
        self._lock = threading.Lock()
        self.dropped = 0

    def put(self, entries: Sequence[LogEntry]) -> None:
        with self._lock:
            room = (self._entries.maxlen or 0) - len(self._entries)
            self.dropped += max(0, len(entries) - room)
            self._entries.extend(entries)

    def take(self) -> list[LogEntry]:
        with self._lock:
            taken = list(self._entries)
            self._entries.clear()
        return taken
