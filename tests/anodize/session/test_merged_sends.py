"""Protocols that need the full merge of sends (LANGUAGE.md 5, issue 17) run, monitored.

C is not told A's choice before it sends; it sends the same message either way and
learns the branch afterwards from B: C's local type is ``!B(x(int)).&B{l1, l2}``.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

import anodize
import sessiontypes
from anodize import Endpoint, ProtocolViolationError

SEND_THEN_LEARN = sessiontypes.loads("""
global G(A, B, C) = A -> B : { l1. C -> B : x(int). B -> C : l1,
                               l2. C -> B : x(int). B -> C : l2 }
""", "merge.proto").globals["G"]

# C sends a reading every round without knowing whether A wants another round.
READINGS = sessiontypes.loads("""
global R(A, B, C) = mu t. A -> B : { more. C -> B : reading(int). B -> C : more. t,
                                     done. C -> B : reading(int). B -> C : done }
""", "readings.proto").globals["R"]


def run(global_type: sessiontypes.GlobalType, **roles: Callable[[Endpoint], None]) -> anodize.RunReport:
    system = anodize.System(global_type, transport=anodize.Inproc())
    group = system.group("all")
    for name, function in roles.items():
        group.role(name, function)
    return system.run(timeout=10)


def test_the_projection_merges_the_sends() -> None:
    assert str(SEND_THEN_LEARN.project("C")) == "!B(x(int)).&B{l1, l2}"
    assert str(READINGS.project("C")) == "mu t.!B(reading(int)).&B{more.t, done}"


@pytest.mark.parametrize("choice", ["l1", "l2"])
def test_the_role_that_is_told_late_runs_either_branch(choice: str) -> None:
    learned: list[str] = []

    def a(ep: Endpoint) -> None:
        ep.send("B", choice)

    def b(ep: Endpoint) -> None:
        picked = ep.recv("A").label
        assert ep.recv("C") == anodize.Message("x", 7)
        ep.send("C", picked)

    def c(ep: Endpoint) -> None:
        ep.send("B", "x", 7)
        learned.append(ep.recv("B").label)

    report = run(SEND_THEN_LEARN, A=a, B=b, C=c)
    assert report.ok, report.summary()
    assert learned == [choice]
    assert report.messages == {"A->B": 1, "C->B": 1, "B->C": 1}


def test_a_loop_of_merged_sends_runs_until_told() -> None:
    sent: list[int] = []

    def a(ep: Endpoint) -> None:
        for _ in range(3):
            ep.send("B", "more")
        ep.send("B", "done")

    def b(ep: Endpoint) -> None:
        while True:
            picked = ep.recv("A").label
            ep.recv("C")
            ep.send("C", picked)
            if picked == "done":
                return

    def c(ep: Endpoint) -> None:
        while True:
            sent.append(len(sent))
            ep.send("B", "reading", sent[-1])
            if ep.recv("B").label == "done":
                return

    report = run(READINGS, A=a, B=b, C=c)
    assert report.ok, report.summary()
    assert sent == [0, 1, 2, 3]
    assert report.messages == {"A->B": 4, "C->B": 4, "B->C": 4}


def test_a_send_outside_the_merged_type_is_blamed_on_the_sender() -> None:
    def a(ep: Endpoint) -> None:
        ep.send("B", "l1")

    def b(ep: Endpoint) -> None:
        ep.recv("A")
        ep.recv("C")

    def c(ep: Endpoint) -> None:
        ep.send("B", "l1")  # C must send x first, whichever branch A took

    report = run(SEND_THEN_LEARN, A=a, B=b, C=c)
    error = report.roles["C"].error
    assert isinstance(error, ProtocolViolationError)
    assert (error.role, error.blame) == ("C", "C")
    assert [str(e) for e in error.expected] == ["!B(x(int))"]
