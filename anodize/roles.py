"""Running one role's function on its thread, and reporting how it ended.

Shared by both transports: the inproc supervisor and a group's process.
"""

from __future__ import annotations

import inspect
import typing
from collections.abc import Callable
from typing import Any

from .endpoint import Endpoint, RoleStopped
from .errors import AnodizeError
from .report import RoleReport
from .sched import apply_thread_scheduling
from .typed import State

__all__ = ["run_role", "argument_for", "describe_error"]


def describe_error(error: BaseException | None) -> str:
    """``"Type: message"`` for peers' ``PeerFailedError`` causes and reports."""
    return f"{type(error).__name__}: {error}" if error else "failed"


def run_role(group: str, priority: int | None, cpus: frozenset[int] | None, role: str,
             function: Callable[..., Any], endpoint: Endpoint,
             report: Callable[[RoleReport], None], schedule: bool = True) -> None:
    """Run ``function`` for ``role`` on the calling thread and ``report`` how it ended.

    ``schedule`` False leaves the thread's scheduling alone (a group process has
    already applied it to the whole process).
    """
    scheduling = ""
    try:
        if schedule:
            scheduling = apply_thread_scheduling(priority, cpus)
        function(argument_for(function, endpoint))
        unfinished = endpoint.unfinished()
        if unfinished:
            raise unfinished[0].end_violation()
    except RoleStopped:
        report(RoleReport(role, group, "stopped", None, scheduling))
    except BaseException as error:  # reported, never swallowed: the supervisor decides
        report(RoleReport(role, group, "failed", error, scheduling))
    else:
        report(RoleReport(role, group, "done", None, scheduling))


def argument_for(function: Callable[..., Any], endpoint: Endpoint) -> Any:
    """The endpoint, or the typed initial state when the function asks for one."""
    try:
        parameters = list(inspect.signature(function).parameters.values())
        hints = typing.get_type_hints(function)
    except (TypeError, ValueError, NameError):
        return endpoint
    if not parameters:
        raise AnodizeError(f"role function {function.__qualname__} must take one argument "
                           "(an Endpoint or the typed initial state)")
    wanted = hints.get(parameters[0].name)
    if isinstance(wanted, type) and issubclass(wanted, State):  # a generated typed state
        return wanted(endpoint)
    return endpoint
