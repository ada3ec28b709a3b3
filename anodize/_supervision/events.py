"""What a runner tells the supervisor: the events of its groups' incarnations.

A runner (threads, processes, or processes joined by a network) turns what happens to the
groups it started into these values; :class:`~.supervisor.Supervisor` acts on them the same
way for every transport.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .._session.logs import LogEntry
from .report import RoleReport

__all__ = ["Event", "Ready", "Counts", "RoleEnded", "GroupFailed", "GroupExited", "Note", "Logged"]


@dataclass(frozen=True, kw_only=True)
class Ready:
    """A group's incarnation is built and waits for "go"."""

    group: str
    incarnation: int
    scheduling: str = ""
    memory_note: str = ""
    pid: int | None = None


@dataclass(frozen=True, kw_only=True)
class Counts:
    """A group incarnation's counters so far (per channel ``"A->B"``), memory in bytes."""

    group: str
    incarnation: int
    at: float  # time.monotonic() when the counts were taken
    sent: dict[str, int] | None = None  # None: this event only measures memory
    received: dict[str, int] | None = None
    waiting: dict[str, int] | None = None  # per channel, the most messages waiting so far
    memory: int | None = None
    peak: int | None = None
    checked: dict[str, int] | None = None  # per constrained interaction, its checks so far
    closest: dict[str, float] | None = None  # and its closest margin to a time bound, in seconds
    timeouts: dict[str, int] | None = None  # and the ``else timeout`` it took


@dataclass(frozen=True, kw_only=True)
class RoleEnded:
    """A role ended (its report says how)."""

    group: str
    incarnation: int
    report: RoleReport


@dataclass(frozen=True, kw_only=True)
class GroupFailed:
    """The group failed as a whole (memory bound, crash, garbled report, death)."""

    group: str
    incarnation: int
    error: BaseException


@dataclass(frozen=True, kw_only=True)
class GroupExited:
    """The incarnation is over: its process exited, or every role thread ended (or was abandoned).

    ``unreported`` says what happened to roles that never reported (e.g. "its thread did
    not stop within the grace period and was abandoned").
    """

    group: str
    incarnation: int
    unreported: str = ""
    details: dict[str, str] = field(default_factory=dict)  # per role, where it says more than ``unreported``


@dataclass(frozen=True, kw_only=True)
class Note:
    """A fact for the group's report (e.g. the watchdog demoted it)."""

    group: str
    text: str


@dataclass(frozen=True, kw_only=True)
class Logged:
    """Records the roles logged (every group's, in time order within a group), and those dropped
    on the way, per severity (:mod:`anodize._session.logs`)."""

    entries: tuple[LogEntry, ...]
    dropped: dict[str, int] = field(default_factory=dict)


Event = Ready | Counts | RoleEnded | GroupFailed | GroupExited | Note | Logged
