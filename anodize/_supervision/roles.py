"""Running one role's function on its thread, and reporting how it ended.

Shared by every transport: the in-process runner and a group's process.
"""

from __future__ import annotations

import os
import traceback
from collections.abc import Callable, Mapping
from typing import Any

from .._isolation.inherit import BoostTable
from .._isolation.sched import apply_thread_scheduling
from .._session.endpoint import Endpoint
from .._session.logs import bind_role
from .._session.typed import argument_for
from ..errors import RoleStopped
from .report import RoleReport, RoleStatus

__all__ = ["run_role", "argument_for", "describe_error", "where_raised"]

_RUNTIME = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the anodize package
_FRAMES_KEPT = 6


def describe_error(error: BaseException | None) -> str:
    """``"Type: message"`` for peers' ``PeerFailedError`` causes and reports."""
    return f"{type(error).__name__}: {error}" if error else "failed"


def where_raised(error: BaseException) -> tuple[str, tuple[str, ...]]:
    """Where ``error`` was raised in the role's own code, and the last frames.

    Returns:
        ``("file.py:12 in fn", frames)``: the innermost frame outside the anodize
        runtime (a violation is raised inside the endpoint, but the fault is at the
        role's call), and up to six innermost frames, one ``file:line in fn`` each.
    """
    frames = traceback.extract_tb(error.__traceback__)
    lines = tuple(f"{f.filename}:{f.lineno} in {f.name}" for f in frames[-_FRAMES_KEPT:])
    own = [f for f in frames if not os.path.abspath(f.filename).startswith(_RUNTIME + os.sep)]
    where = f"{own[-1].filename}:{own[-1].lineno} in {own[-1].name}" if own else ""
    return where, lines


def run_role(group: str, priority: int | None, cpus: frozenset[int] | None, role: str,
             function: Callable[..., Any], endpoint: Endpoint,
             report: Callable[[RoleReport], None], schedule: bool = True,
             inheritance: BoostTable | None = None, nice: int | None = None,
             params: Mapping[str, object] | None = None) -> None:
    """Run ``function`` for ``role`` on the calling thread and ``report`` how it ended.

    ``schedule`` False leaves the thread's scheduling alone (a group process has
    already applied it to the whole process). ``inheritance``: the run's priority
    inheritance table, which learns this thread and forgets it when the role ends. ``nice``: the
    group's nice value, applied where it asked no priority. ``params``: the role's parameters,
    checked (``System.check_params``), passed as keyword arguments.
    """
    scheduling = ""
    bind_role(role)  # what this thread logs is the role's (anodize._session.logs)
    try:
        if schedule:
            scheduling = apply_thread_scheduling(priority, cpus, nice)
        if inheritance is not None:
            inheritance.enter(role)
        try:
            function(argument_for(function, endpoint), **(params or {}))
        finally:
            if inheritance is not None:  # before the report: no boost outlives the role
                inheritance.leave(role)
        unfinished = endpoint.unfinished()
        if unfinished:
            raise unfinished[0].end_violation()
    except RoleStopped as stop:
        report(RoleReport(name=role, group=group, status=RoleStatus.STOPPED, scheduling=scheduling,
                          detail=stop.detail))
    except BaseException as error:  # reported, never swallowed: the supervisor decides
        where, frames = where_raised(error)
        report(RoleReport(name=role, group=group, status=RoleStatus.FAILED, error=error,
                          scheduling=scheduling, where=where, traceback=frames))
    else:
        report(RoleReport(name=role, group=group, status=RoleStatus.DONE, scheduling=scheduling))
