"""The roles' log records: what each carries, and how a group captures them without waiting.

Roles log with Python's :mod:`logging`: through their endpoint's logger (``ep.logger``,
a :class:`logging.Logger` named after the role, as a ROS node's logger is named after the
node) or any logger of their own (``logging.getLogger(__name__)``). Wherever roles run (a
group's process, or threads of the supervisor's process), one :class:`LogCapture` handler
on the root logger turns each record a role emits into a :class:`LogEntry` (role, group,
severity, wall and monotonic time, logger, place) and keeps it in a bounded queue. A
record is the role's when its thread runs the role (:func:`bind_role`, set by the runner)
or when its logger is named after a role of the group (a thread the role started, using
``ep.logger``). Nothing in ``emit`` waits: when the queue is full the record is dropped and
counted per severity (unformatted), so a role logging in a tight loop runs on as fast as
:mod:`logging` makes its records.
The runner drains the queue (:meth:`LogCapture.drain`) and carries the entries to the
supervisor.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["LogEntry", "LogCapture", "bind_role", "role_logger", "severity_name", "ros_log", "CAPACITY", "MAX_TEXT",
           "SEVERITIES", "ROSOUT", "LOG_TYPE", "ROS_LEVELS"]

CAPACITY = 1000   # entries a capture holds until its runner drains them; beyond, records are dropped
MAX_TEXT = 2000   # characters of a message kept (a control frame carries a batch of them)
SEVERITIES = ("DEBUG", "INFO", "WARN", "ERROR", "FATAL")  # ROS's names, lowest first
ROS_LEVELS = {"DEBUG": 10, "INFO": 20, "WARN": 30, "ERROR": 40, "FATAL": 50}  # rcl_interfaces/msg/Log's bytes
ROSOUT = "/rosout"                  # where ROS 2 nodes publish their log records
LOG_TYPE = "rcl_interfaces/msg/Log"  # what they publish there

_bound = threading.local()


@dataclass(frozen=True)
class LogEntry:
    """One record a role logged.

    Attributes:
        role: the role that logged it.
        group: the role's group.
        level: Python's level number (``logging.INFO`` ...); :func:`severity_name` gives ROS's name.
        logger: the logger's name (the role's own: the role's name).
        message: the formatted message (with the exception's traceback, if one was logged),
            at most :data:`MAX_TEXT` characters.
        wall: seconds since the epoch when it was logged.
        monotonic: ``time.monotonic()`` when it was logged (one clock for every process of the machine).
        file: the source file of the logging call.
        function: the function of the logging call.
        line: the line of the logging call.
    """

    role: str
    group: str
    level: int
    logger: str
    message: str
    wall: float
    monotonic: float
    file: str = ""
    function: str = ""
    line: int = 0

    @property
    def severity(self) -> str:
        """ROS's name of the level: DEBUG, INFO, WARN, ERROR or FATAL."""
        return severity_name(self.level)


def severity_name(level: int) -> str:
    """ROS's severity for Python's ``level`` (WARNING is WARN, CRITICAL is FATAL; in between, the lower)."""
    if level >= logging.CRITICAL:
        return "FATAL"
    if level >= logging.ERROR:
        return "ERROR"
    if level >= logging.WARNING:
        return "WARN"
    if level >= logging.INFO:
        return "INFO"
    return "DEBUG"


def ros_log(entry: LogEntry) -> object:
    """``entry`` as ROS 2's ``rcl_interfaces/msg/Log`` (rosbags' class): stamp, level, name (the
    role), msg, file, function, line, as a node's record on ``/rosout``."""
    from .._ros import ros_type

    log_type = ros_type(LOG_TYPE)
    stamp_type = ros_type("builtin_interfaces/msg/Time")
    seconds = int(entry.wall // 1)
    stamp = stamp_type.cls(sec=seconds, nanosec=min(999_999_999, int((entry.wall - seconds) * 1e9)))
    return log_type.cls(stamp=stamp, level=ROS_LEVELS[entry.severity], name=entry.role, msg=entry.message,
                        file=entry.file, function=entry.function, line=max(0, min(entry.line, 2**32 - 1)))


def bind_role(role: str | None) -> None:
    """Records logged on the calling thread are ``role``'s from now on (None: no role's)."""
    _bound.role = role


def role_logger(role: str) -> logging.Logger:
    """``role``'s logger: named after it, at INFO unless someone set its level (as ROS's default)."""
    logger = logging.getLogger(role)
    if logger.level == logging.NOTSET:
        logger.setLevel(logging.INFO)
    return logger


class LogCapture(logging.Handler):
    """The handler that captures the records of a set of roles (see the module docstring).

    Args:
        groups: role -> group, for every role whose records it captures.
        capacity: entries held before records are dropped.
    """

    def __init__(self, groups: Mapping[str, str], capacity: int = CAPACITY) -> None:
        super().__init__(logging.NOTSET)
        self.groups = dict(groups)
        self.capacity = capacity
        self._entries: deque[LogEntry] = deque()
        self._dropped: dict[str, int] = {}
        self._lock = threading.Lock()

    def emit(self, record: logging.LogRecord) -> None:
        role = getattr(_bound, "role", None)
        if role is None or role not in self.groups:
            role = record.name if record.name in self.groups else None
        if role is None:  # not a role's record: some other handler's business, else Python's last resort
            last = logging.lastResort
            if last is not None and record.levelno >= last.level and logging.getLogger().handlers == [self]:
                last.handle(record)  # as if we were not here (stderr, WARNING and above)
            return
        if len(self._entries) >= self.capacity:  # checked before formatting: a flood costs little
            name = severity_name(record.levelno)
            with self._lock:
                self._dropped[name] = self._dropped.get(name, 0) + 1
            return
        try:
            text = record.getMessage()
            if record.exc_info and record.exc_info[0] is not None:
                text = f"{text}\n{logging.Formatter().formatException(record.exc_info)}"
        except Exception:  # a bad format string is the role's mistake: logging reports it, we do not fail
            self.handleError(record)
            return
        self._entries.append(LogEntry(
            role=role, group=self.groups[role], level=record.levelno, logger=record.name, message=text[:MAX_TEXT],
            wall=record.created, monotonic=time.monotonic(), file=record.pathname, function=record.funcName,
            line=record.lineno or 0))

    def drain(self, limit: int | None = None) -> tuple[list[LogEntry], dict[str, int]]:
        """Take up to ``limit`` entries (all, if None), oldest first, and the records dropped since
        the last drain, per severity."""
        taken: list[LogEntry] = []
        while self._entries and (limit is None or len(taken) < limit):
            taken.append(self._entries.popleft())
        with self._lock:
            dropped, self._dropped = self._dropped, {}
        return taken, dropped

    def install(self, root_level: int | None = None) -> None:
        """Capture from now on: on the root logger, with the roles' loggers at INFO (unless set).

        ``root_level``: the root logger's level to set too (a group's own process sets INFO, so
        that a role's ``logging.getLogger(__name__)`` logs INFO as its endpoint's logger does;
        in the caller's process its level is the caller's).
        """
        for role in self.groups:
            role_logger(role)
        root = logging.getLogger()
        if root_level is not None:
            root.setLevel(root_level)
        root.addHandler(self)

    def uninstall(self) -> None:
        """Capture no more."""
        logging.getLogger().removeHandler(self)
