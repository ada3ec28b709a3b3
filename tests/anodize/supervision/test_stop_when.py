"""``System.run(stop_when=...)``: a caller that knows the mission is done ends a run of endless loops."""

from __future__ import annotations

import threading
from collections.abc import Callable

import anodize
import sessiontypes
from anodize import Endpoint

FOREVER = sessiontypes.loads("global F = mu t. A -> B : tick. t").globals["F"]


def _run(heard: list[int], stop_when: Callable[[], str | None], timeout: float = 60.0) -> anodize.RunReport:
    """A ticker and a listener that loop forever; the listener counts into ``heard``."""
    def ticker(ep: Endpoint) -> None:
        while True:
            ep.send("B", "tick")
            threading.Event().wait(0.005)

    def listener(ep: Endpoint) -> None:
        while True:
            ep.recv("A")
            heard.append(1)

    system = anodize.System(FOREVER)
    system.group("all").role("A", ticker).role("B", listener)
    return system.run(timeout=timeout, stop_when=stop_when)


def test_stop_when_ends_the_run_before_its_timeout_with_its_reason() -> None:
    heard: list[int] = []

    def done() -> str | None:
        return "the listener heard 20 ticks" if len(heard) >= 20 else None

    report = _run(heard, done)
    assert "stopping every group: the listener heard 20 ticks" in report.notes
    assert not any("the timeout passed" in note for note in report.notes)
    assert {role.status for role in report.roles.values()} == {"stopped"}
    assert len(heard) >= 20


def test_stop_when_without_a_reason_leaves_the_timeout_to_stop_the_run() -> None:
    asked: list[int] = []

    def never() -> str | None:
        asked.append(1)
        return None

    report = _run([], never, timeout=1.2)
    assert "stopping every group: the timeout passed" in report.notes
    assert asked  # it was asked while the run went


def test_a_stop_when_that_raises_is_reported_and_asked_no_more_and_the_run_ends_at_its_timeout() -> None:
    asked: list[int] = []

    def broken() -> str | None:
        asked.append(1)
        raise KeyError("mission")

    report = _run([], broken, timeout=1.5)
    assert "stop_when raised KeyError: 'mission'; it is asked no more, and the run goes on to its timeout" \
        in report.notes, report.notes
    assert "stopping every group: the timeout passed" in report.notes
    assert asked == [1]
