"""Where the roles' log records go once they reach the supervisor: the caller's ``on_log``,
every tap that takes them (a recording's ``/rosout``, the live view's Log panel) and the
runner, when it publishes them (on DDS, ROS's ``/rosout``)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

from .._session.logs import LogEntry

__all__ = ["log_receivers"]

Receiver = Callable[[Sequence[LogEntry]], None]


def log_receivers(on_log: Receiver | None, *holders: Iterable[object] | object) -> Receiver | None:
    """One receiver handing each batch to ``on_log`` and to the ``log`` method of every object
    in ``holders`` (each an object, or an iterable of them, e.g. the taps) that has one;
    None when nothing takes records. The taps and runner come first: the terminal last."""
    receivers: list[Receiver] = []
    for holder in holders:
        for item in (holder if isinstance(holder, (list, tuple)) else (holder,)):
            method = getattr(item, "log", None)
            if callable(method):
                receivers.append(method)
    if on_log is not None:
        receivers.append(on_log)
    if not receivers:
        return None

    def each(entries: Sequence[LogEntry]) -> None:
        for receive in receivers:
            receive(entries)
    return each
