"""The roles' log records on their way from a group's process to the supervisor.

A group drains its :class:`~anodize._session.logs.LogCapture` at each heartbeat and sends
what it took as :class:`~.control.Logs` messages of at most :data:`BATCH` records (a control
frame stays far below its limit); the supervisor's runner turns each back into entries.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence

from .._session.logs import LogEntry
from .control import Logs

__all__ = ["BATCH", "to_messages", "from_message"]

BATCH = 100  # records per Logs message: 100 x (2000 characters, up to 4 bytes each) < 1 MiB


def to_messages(entries: Sequence[LogEntry], dropped: Mapping[str, int]) -> Iterator[Logs]:
    """``entries`` in batches of :data:`BATCH`; the first carries ``dropped`` (none when nothing to say)."""
    if not entries and not dropped:
        return
    first = True
    for start in range(0, max(len(entries), 1), BATCH):
        batch = entries[start:start + BATCH]
        yield Logs(roles=tuple(e.role for e in batch), levels=tuple(max(0, e.level) for e in batch),
                   loggers=tuple(e.logger for e in batch), messages=tuple(e.message for e in batch),
                   walls=tuple(e.wall for e in batch), monotonics=tuple(e.monotonic for e in batch),
                   files=tuple(e.file for e in batch), functions=tuple(e.function for e in batch),
                   lines=tuple(e.line for e in batch), dropped=dict(dropped) if first else {})
        first = False


def from_message(message: Logs, group: str, roles: Sequence[str]) -> list[LogEntry]:
    """The entries ``message`` carries from ``group``, whose roles are ``roles``.

    Raises:
        ValueError: its columns differ in length, or it names a role not of the group.
    """
    columns = (message.roles, message.levels, message.loggers, message.messages, message.walls,
               message.monotonics, message.files, message.functions, message.lines)
    if len({len(c) for c in columns}) != 1:
        raise ValueError("a Logs message whose columns differ in length")
    strangers = sorted(set(message.roles) - set(roles))
    if strangers:
        raise ValueError(f"a Logs message names roles not of group {group}: {', '.join(strangers)}")
    return [LogEntry(role=role, group=group, level=level, logger=logger, message=text, wall=wall,
                     monotonic=monotonic, file=file, function=function, line=line)
            for role, level, logger, text, wall, monotonic, file, function, line in zip(*columns, strict=True)]
