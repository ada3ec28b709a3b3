"""The time a role reads (``Endpoint.now()``, ``Endpoint.wall()``): a clock its network gives it.

A role that reads ``time.monotonic()`` itself makes what it sends depend on when it ran,
which a replay cannot give back. Read through its endpoint, the same code runs on:

- the machine's clock, live (:data:`LIVE`: ``time.monotonic()`` and ``time.time()``);
- the machine's clock, each reading also recorded, in a recorded run (the recording's
  clocks, :mod:`anodize._recording.tap`);
- the replay's clock in ``anodize replay`` (:mod:`anodize._recording.replay_network`): the
  readings the recording holds, in order, else the time of the message just received.

A network names its roles' clocks in an optional ``clocks`` mapping (role -> clock);
a role it names none for reads the machine's. Readings are kept apart per endpoint (a
role's own, and each parallel branch's: ``branch`` is ``""``, ``"1"``, ``"2"``, ``"1.2"``,
...), so the threads of a role that forks read their own sequences.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Protocol

__all__ = ["Clock", "LiveClock", "LIVE", "clock_of", "adopt_clocks"]


class Clock(Protocol):
    """What a role's endpoint reads time from."""

    def now(self, branch: str) -> float:
        """Monotonic seconds (only differences mean anything)."""

    def wall(self, branch: str) -> float:
        """Seconds since the epoch (for stamps)."""


class LiveClock:
    """The machine's clock."""

    def now(self, branch: str) -> float:
        return time.monotonic()

    def wall(self, branch: str) -> float:
        return time.time()


LIVE = LiveClock()


def clock_of(network: object, role: str) -> Clock:
    """``role``'s clock on ``network``: the one its ``clocks`` names, else the machine's."""
    clocks: Mapping[str, Clock] | None = getattr(network, "clocks", None)
    found = clocks.get(role) if clocks else None
    return LIVE if found is None else found


def adopt_clocks(network: object, source: object) -> None:
    """Give ``network`` the clocks ``source`` (a group's channel tap) keeps for its roles, if
    it keeps any (its ``clocks()``): a recording records every reading of its roles' clocks.
    Called before the roles' endpoints are made."""
    offered = getattr(source, "clocks", None)
    if offered is None:
        return
    clocks: Mapping[str, Clock] = offered()
    if not clocks:
        return
    mine: dict[str, Clock] | None = getattr(network, "clocks", None)
    if mine is None:
        mine = {}
        setattr(network, "clocks", mine)  # noqa: B010 - a network class need not declare it
    mine.update(clocks)
