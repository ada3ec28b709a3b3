"""The seams of the supervision core: what a transport's runner does for the supervisor
(:class:`Runner`, over the part of the system it runs, :class:`Scope`), and, when groups run on
other hosts, the line to their supervisors (:class:`Link`, within :class:`Elsewhere`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from .events import Event
from .group import Group
from .hostview import LOST_AFTER
from .words import Word

__all__ = ["Runner", "Scope", "Link", "Elsewhere", "LINGER"]

LINGER = 15.0  # seconds a supervisor that stopped the run waits for a host cut off meanwhile to hear it


class Link(Protocol):
    """This host's line to the supervisors of the same run on other hosts."""

    host: str
    supervisor: str  # this supervisor's id, drawn at random (a second one claiming our groups has another)

    def say(self, word: Word) -> None:
        """Tell every other host."""

    def words(self) -> list[Word]:
        """What the others said since the last call."""


@dataclass(frozen=True)
class Elsewhere:
    """The whole system, when some of its groups run on other hosts under their own supervisors.

    Attributes:
        link: to those supervisors.
        groups: every group of the system (their policies decide restart sets).
        channels: every channel of the system.
        lost_after: seconds without a word from a supervisor before its host counts as lost.
        linger: seconds a supervisor that stopped the run while a host was lost waits for it to
            come back and hear so.
    """

    link: Link
    groups: dict[str, Group]
    channels: tuple[tuple[str, str], ...]
    lost_after: float = LOST_AFTER
    linger: float = LINGER


@dataclass(frozen=True)
class Scope:
    """The part of a system one runner runs: every group, but on DDS only this host's.

    Attributes:
        groups: the groups this runner starts, by name.
        roles: their roles, in the global type's order.
        channels: the channels between those roles.
        elsewhere: the whole system, when some of its groups run on other hosts.
    """

    groups: dict[str, Group]
    roles: tuple[str, ...]
    channels: tuple[tuple[str, str], ...]
    elsewhere: Elsewhere | None = None


class Runner(Protocol):
    """What a transport does for the supervisor (a transport value builds it from a run's plan)."""

    transport: str
    scope: Scope

    def start(self, groups: Sequence[str], incarnation: int) -> None:
        """Start ``groups`` together on fresh channels among them; roles of any other group
        are gone to them. Each reports :class:`~.events.Ready`, then waits for :meth:`go`."""

    def go(self, group: str) -> None:
        """Let a ready group's roles run."""

    def events(self, timeout: float) -> list[Event]:
        """What happened, waiting up to ``timeout`` seconds for the first event."""

    def tell_failed(self, group: str, role: str, cause: str) -> None:
        """Tell ``group`` that ``role`` (of another group) failed."""

    def stop(self, group: str) -> None:
        """Ask ``group``'s roles to stop (they get ``RoleStopped``)."""

    def kill(self, group: str) -> None:
        """End ``group`` now; it still reports :class:`~.events.GroupExited`."""

    def notes(self) -> list[str]:
        """System-wide facts for the report."""

    def bound(self, seconds: float) -> None:
        """The run will end within ``seconds`` from now (its timeout and grace): a runner whose
        roles share the supervisor's process arms a last resort for a role that never lets the
        supervisor run again; others need nothing."""

    def close(self) -> None:
        """Release everything (processes, cgroups, rings); called once, at the end."""
