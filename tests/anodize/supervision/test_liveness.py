"""The liveness rule on synthetic samples: alive, starved, frozen, holding the GIL."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from anodize._isolation.procstat import ProcSample
from anodize._supervision.liveness import (
    BUSY_SHARE,
    STARVATION_BOUND,
    Alive,
    Frozen,
    HoldingGil,
    StallLog,
    Starved,
    judge,
    overlap,
    stall,
    waited_between,
)

LIMIT = 2.0


def judge_(*, silent: float, limit: float, stalled: float, before: ProcSample | None,
           now: ProcSample | None) -> object:
    """judge() with the wait measured between the two looks (as if no look came between)."""
    waited = waited_between(before, now) if before is not None and now is not None else 0.0
    return judge(silent=silent, limit=limit, stalled=stalled, waited=waited, before=before, now=now)


def look(at: float, cpu: float = 0.0, waited: float = 0.0, state: str = "S", extra: float | None = None,
         ran: float | None = None) -> ProcSample:
    """A process with a main thread (1) that ran ``ran`` (default: all its CPU time) and,
    optionally, a second one (2) that waited ``extra``."""
    waits = {1: waited} if extra is None else {1: waited, 2: extra}
    runs = {1: cpu if ran is None else ran} if extra is None else {1: cpu if ran is None else ran, 2: 0.0}
    return ProcSample(at=at, cpu=cpu, waited=waits, ran=runs, slices=dict.fromkeys(waits, 7),
                      states=dict.fromkeys(waits, state), cpus=frozenset({0}))


def test_within_the_limit_is_alive_whatever_the_kernel_says() -> None:
    assert judge_(silent=1.9, limit=LIMIT, stalled=0, before=None, now=look(10, state="T")) == Alive()


def test_the_supervisors_own_stall_is_not_counted_against_the_group() -> None:
    # Every group silent 4.8 s because the supervisor did not run for 4 s of it: alive.
    assert judge_(silent=4.8, limit=LIMIT, stalled=4.0, before=None, now=None) == Alive()
    verdict = judge_(silent=4.8, limit=LIMIT, stalled=2.0, before=None, now=None)
    assert isinstance(verdict, Frozen) and "heartbeats decide" in verdict.why


def test_a_stopped_process_is_frozen_at_once_past_the_limit() -> None:
    verdict = judge_(silent=2.1, limit=LIMIT, stalled=0, before=look(0), now=look(2.1, waited=2.0, state="T"))
    assert isinstance(verdict, Frozen) and "SIGSTOP" in verdict.why


def test_runnable_but_not_given_the_cpu_is_starved_not_failed() -> None:
    verdict = judge_(silent=4.0, limit=LIMIT, stalled=0, before=look(0, waited=1.0),
                    now=look(4.0, cpu=0.01, waited=4.8, state="R"))
    assert verdict == Starved(4.0, 3.8)


def test_one_thread_waiting_counts_not_the_sum_of_all() -> None:
    before, now = look(0, extra=0.0), look(4.0, waited=1.5, extra=1.5)
    assert waited_between(before, now) == 1.5
    assert isinstance(judge_(silent=4.0, limit=LIMIT, stalled=0, before=before, now=now), Frozen)


def test_a_thread_still_on_the_run_queue_counts_as_waiting() -> None:
    # Throttled by a CPU quota: runnable at both looks, 0.01 s on the CPU in 4 s, no wait
    # counted yet (the kernel counts a wait when it ends).
    before, now = look(0, cpu=1.0, state="R"), look(4.0, cpu=1.01, state="R")
    assert waited_between(before, now) == pytest.approx(3.99)
    assert isinstance(judge_(silent=4.0, limit=LIMIT, stalled=0, before=before, now=now), Starved)
    # Runnable at both looks but on the CPU all along: the GIL, not starvation.
    assert waited_between(look(0, state="R"), look(4.0, cpu=4.0, state="R")) == 0.0


def test_a_thread_born_in_the_window_counts_from_zero() -> None:
    assert waited_between(look(0), look(4.0, extra=3.0)) == 3.0


def test_a_process_that_ran_and_sent_nothing_holds_the_gil() -> None:
    verdict = judge_(silent=2.2, limit=LIMIT, stalled=0, before=look(0, cpu=5.0), now=look(2.2, cpu=7.1, state="R"))
    assert isinstance(verdict, HoldingGil) and verdict.cpu > 2


def test_a_process_asleep_with_no_heartbeat_is_frozen() -> None:
    verdict = judge_(silent=2.2, limit=LIMIT, stalled=0, before=look(0, cpu=5.0), now=look(2.2, cpu=5.0))
    assert isinstance(verdict, Frozen) and verdict.why.startswith("asleep")


def test_a_call_holding_the_gil_is_failed_although_the_machine_is_busy() -> None:
    # On a busy machine it waits for the CPU 80% of the time, but the 20% it runs is far
    # more than a heartbeat needs.
    verdict = judge_(silent=3.5, limit=LIMIT, stalled=0, before=look(0, cpu=1.0),
                     now=look(3.5, cpu=1.7, waited=2.8, state="R"))
    assert isinstance(verdict, HoldingGil) and verdict.charged < LIMIT


def test_the_cpu_of_a_first_look_before_the_last_heartbeat_counts_pro_rata() -> None:
    # Looked at 0.3 s before its last heartbeat, busy on a whole CPU until then (a healthy busy
    # group), then starved for 2.2 s: not 0.3 s of CPU while silent, but 0.3 * 2.2 / 2.5.
    before, now = look(0, cpu=0.0), look(2.5, cpu=0.3, waited=2.2, state="R")
    assert isinstance(judge_(silent=2.2, limit=LIMIT, stalled=0, before=before, now=now), Starved)


def test_a_starved_group_that_then_runs_and_says_nothing_is_failed() -> None:
    # Starved for 3 s, then 2.5 s on the CPU (holding the GIL) without a heartbeat.
    verdict = judge_(silent=5.5, limit=LIMIT, stalled=0, before=look(0), now=look(5.5, cpu=2.5, waited=3.0))
    assert isinstance(verdict, HoldingGil) and verdict.charged == 2.5


def test_starvation_is_not_an_excuse_forever() -> None:
    silent = STARVATION_BOUND * LIMIT + 0.5
    verdict = judge_(silent=silent, limit=LIMIT, stalled=0, before=look(0), now=look(silent, waited=silent))
    assert isinstance(verdict, Frozen) and "bound" in verdict.why


def test_the_stall_and_the_wait_are_not_both_excused() -> None:
    # The machine stalled for 2 s: supervisor and group alike. 3 s of silence remain charged.
    verdict = judge_(silent=5.0, limit=LIMIT, stalled=2.0, before=look(0), now=look(5.0, waited=2.0))
    assert isinstance(verdict, Frozen)


samples = st.floats(min_value=0, max_value=100, allow_nan=False)


@given(silent=samples, stalled=samples, cpu=samples, waited=samples, stopped=st.booleans())
def test_no_group_is_failed_within_the_limit_of_time_it_could_run(silent: float, stalled: float, cpu: float,
                                                                   waited: float, stopped: bool) -> None:
    now = look(silent, cpu=cpu, waited=waited, state="T" if stopped else "R")
    verdict = judge_(silent=silent, limit=LIMIT, stalled=stalled, before=look(0), now=now)
    if (silent - max(stalled, min(waited, silent)) <= LIMIT and silent <= STARVATION_BOUND * LIMIT and not stopped
            and cpu < BUSY_SHARE * LIMIT):
        assert isinstance(verdict, Alive | Starved)
    if silent - stalled > LIMIT and stopped:
        assert isinstance(verdict, Frozen)


@given(silent=samples, waited=samples, cpu=samples)
def test_a_failed_verdict_always_had_more_than_the_limit_to_run_in(silent: float, waited: float, cpu: float) -> None:
    verdict = judge_(silent=silent, limit=LIMIT, stalled=0, before=look(0), now=look(silent, cpu=cpu, waited=waited))
    if isinstance(verdict, HoldingGil):
        assert verdict.cpu >= BUSY_SHARE * LIMIT and silent > LIMIT
    if isinstance(verdict, Frozen):
        assert silent - min(waited, silent) > LIMIT or silent > STARVATION_BOUND * LIMIT
    if isinstance(verdict, Starved):
        assert verdict.silent > LIMIT and verdict.silent - verdict.waited <= LIMIT


def test_the_stall_log_keeps_episodes_and_measures_their_overlap() -> None:
    log = StallLog(horizon=10.0, least=0.05)
    log.add(5.0, 2.0)   # 3..5
    log.add(6.0, 0.01)  # too short to count
    log.add(9.0, 1.0)   # 8..9
    assert log.count == 2 and log.longest == 2.0
    assert log.within(4.0, 8.5) == 1.5
    log.add(30.0, 0.0)  # older than the horizon: forgotten
    assert log.within(0.0, 30.0) == 0.0


def test_overlap_of_disjoint_episodes() -> None:
    assert overlap([(0.0, 1.0), (2.0, 4.0)], 0.5, 3.0) == 1.5


def test_a_stall_is_the_late_wake_or_the_run_queue_wait_whichever_is_larger() -> None:
    assert stall(expected=1.0, woke=1.3, queued=0.1) == pytest.approx(0.3)
    assert stall(expected=None, woke=1.3, queued=0.2) == 0.2
    assert stall(expected=2.0, woke=1.3, queued=None) == 0.0


def test_time_away_from_the_loop_is_a_stall_too() -> None:
    # Stopped (SIGSTOP) while handling events: not runnable, so no run-queue wait, but away.
    assert stall(expected=None, woke=5.0, queued=0.0, away=3.0) == 3.0


def test_a_thread_put_on_a_cpu_in_between_is_judged_by_the_kernels_count() -> None:
    # A thread waiting for the GIL wakes every 5 ms (runnable at both looks by chance, but put
    # on a CPU many times): it did not wait for a CPU; the kernel's count says so.
    before = ProcSample(at=0, cpu=0, waited={1: 0.0}, ran={1: 0.0}, slices={1: 10}, states={1: "R"}, cpus=frozenset())
    now = ProcSample(at=2.0, cpu=0, waited={1: 0.01}, ran={1: 0.02}, slices={1: 410}, states={1: "R"},
                     cpus=frozenset())
    assert waited_between(before, now) == pytest.approx(0.01)


def test_a_wait_is_never_longer_than_the_time_between_the_looks() -> None:
    assert waited_between(look(0, waited=0.0), look(1.0, waited=5.0)) == 1.0
