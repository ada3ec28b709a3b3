"""The Route protocol (a choice whose branches go to different receivers) written against its
generated typed states.

mypy --strict accepts this program; the tests also run it on anodize's runtime.
"""

from __future__ import annotations

from typing import assert_never

import route_a
import route_b
import route_c

PLAN = ["B", "C", "C", "B"]


def chooser(start: route_a.Initial) -> route_a.End:
    state = start
    for number, worker in enumerate(PLAN):
        if worker == "B":
            state = state.select_b_job(number).recv_ok()
        else:
            result, state = state.select_c_job(number).recv_result()
            assert result == number * 10
    return state.select_b_stop()


def worker_b(start: route_b.Initial) -> route_b.End:
    state = start
    while True:
        outcome = state.offer()
        match outcome:
            case route_b.State0FromAJob(_, idle):
                state = idle.send_idle()
            case route_b.State0FromCWork(work, answering):
                state = answering.send_result(work * 10)
            case route_b.State0FromAStop(stopping):
                return stopping.send_stop()
            case _:
                assert_never(outcome)


def worker_c(start: route_c.Initial) -> route_c.End:
    state = start
    while True:
        outcome = state.offer()
        match outcome:
            case route_c.State0FromBIdle(acknowledging):
                state = acknowledging.send_ok()
            case route_c.State0FromAJob(job, working):
                state = working.send_work(job)
            case route_c.State0FromBStop(end):
                return end
            case _:
                assert_never(outcome)
