"""Where the roles' log records go once they reach the supervisor: the caller's ``on_log``,
every tap that takes them (a recording's ``/rosout``, the live view's Log panel) and the
runner, when it publishes them (on DDS, ROS's ``/rosout``)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

from .._session.logs import LogEntry

__all__ = ["LogFanout", "log_receivers"]

Receiver = Callable[[Sequence[LogEntry]], None]


class LogFanout:
    """Hands each batch to every receiver in turn. One that raises is handed no more (the others
    still are) and :attr:`problems` says so, for the run's notes."""

    def __init__(self, receivers: list[tuple[str, Receiver]]) -> None:
        self.receivers = receivers
        self.problems: list[str] = []

    def __call__(self, entries: Sequence[LogEntry]) -> None:
        for name, receive in list(self.receivers):
            try:
                receive(entries)
            except Exception as error:  # a receiver's failure ends neither logging nor the run
                self.receivers.remove((name, receive))
                self.problems.append(f"logging: {name} raised {type(error).__name__}: {error}; "
                                     "it is handed no more records")


def log_receivers(on_log: Receiver | None, taps: Iterable[object], runner: object) -> LogFanout | None:
    """The fan-out to the ``log`` method of each of ``taps`` and of ``runner`` that has one, then to
    ``on_log`` (the terminal last); None when nothing takes records."""
    receivers: list[tuple[str, Receiver]] = []
    for item in (*taps, runner):
        method = getattr(item, "log", None)
        if callable(method):
            receivers.append((type(item).__name__, method))
    if on_log is not None:
        receivers.append(("on_log", on_log))
    return LogFanout(receivers) if receivers else None
