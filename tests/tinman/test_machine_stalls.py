"""When a TinMan run's failure counts as the machine's stall (machine_stalls.py), which the
TinMan tests then run once more: only missed periods and deadlines, no later than the
supervisor's own SCHED_FIFO thread was held up in the same run."""

from __future__ import annotations

from typing import Any

from machine_stalls import machine_stalled, once_more_if_the_machine_stalled

JOY = ("group control failed: DeadlineMissedError: protocol TinManParallel, role Joy: protocol violation by Joy: "
       "period missed: sent 122.201 ms after the interaction's previous send, 87.201 ms too late for every 20ms "
       "+- 15ms; in state 0 (!Control(Joy) every 20ms +- 15ms.c)")
MOVE = ("group planning failed: PeerFailedError: role Planner: peer Move failed (DeadlineMissedError: protocol "
        "TinManParallel, role Move: protocol violation by Control: deadline missed: nothing from Control within "
        "100.000 ms of Move's previous action")
HELD = ("liveness: the supervisor's watching thread ran at SCHED_FIFO 1; a group is failed after 2 s without a "
        "heartbeat in which it could run; the supervisor itself was held up 7 times (longest {held} s), not "
        "counted against the groups")


def report(*problems: str, held: float | None = 0.18) -> dict[str, Any]:
    notes = [HELD.format(held=held)] if held is not None else []
    return {"ok": not problems, "problems": ["2 protocol violations", *problems], "notes": notes}


def test_missed_deadlines_no_later_than_the_machine_stalled_are_the_machines() -> None:
    why = machine_stalled(report(JOY, MOVE))
    assert why is not None and "87.2 ms late" in why and "held up 180 ms" in why


def test_anything_else_is_the_runs_own() -> None:
    assert machine_stalled(report()) is None  # it passed
    assert machine_stalled(report(JOY, MOVE, held=0.05)) is None  # later than any stall measured
    assert machine_stalled(report(JOY, MOVE, held=None)) is None  # no stall measured at all
    violation = "group control failed: ProtocolViolationError: role Joy: expected !Control(Joy), got !Move(Twist)"
    assert machine_stalled(report(JOY, violation)) is None  # a failure of another kind


def test_an_inconclusive_run_is_run_once_more_and_only_once() -> None:
    runs = iter([(1, report(JOY)), (1, report(JOY)), (0, report())])
    assert once_more_if_the_machine_stalled(lambda: next(runs)) == (1, report(JOY))  # the second is final
    passing = iter([(0, report()), (1, report(JOY))])
    assert once_more_if_the_machine_stalled(lambda: next(passing)) == (0, report())
