"""The liveness rule: alive, starved, frozen, or a call holding the GIL.

A group process sends a heartbeat four times a second. Missing heartbeats alone do
not say *why* it is silent, and on a busy machine the answer decides whether to kill
it. This module decides from samples and nothing else (no clock, no ``/proc``), so
the rule can be tested on synthetic numbers:

- the silence is what passed since the group's last heartbeat was *sent* (its own
  timestamp: data that sat unread in the control pipe is not silence);
- minus the time the supervisor itself did not run (:class:`StallLog`): it never
  blames a group for a gap in which it could not have looked;
- minus the time the group was runnable but not given a CPU (the largest growth of a
  thread's run-queue wait): that is **starvation**, reported, not failed;
- past the limit the group is failed: **frozen** when it is stopped (at once); **holding
  the GIL** when, silent, it used ``BUSY_SHARE`` x the limit of CPU (a heartbeat needs
  milliseconds of it: a process that ran that long and sent none is running a call that
  does not let its heartbeat thread have the GIL); **frozen** when its *charged* silence
  (what remains) passes the limit although it slept (no CPU, no wait: its heartbeat
  thread should have run and did not).

Starvation is not an excuse forever: a starved group that gets the CPU and still says
nothing is failed once it has used that much CPU, or slept that long, and no group is
let off for more than ``STARVATION_BOUND`` times the limit of silence in all.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

from .._isolation.procstat import ProcSample

__all__ = ["Alive", "Starved", "Frozen", "HoldingGil", "Verdict", "judge", "StallLog", "STARVATION_BOUND",
           "BUSY_SHARE"]

STARVATION_BOUND = 10  # times the limit: the longest silence starvation can excuse
BUSY_SHARE = 0.3  # x the limit: CPU seconds a silent process may use before it counts as running code


@dataclass(frozen=True)
class Alive:
    """Within the limit once the supervisor's own stalls are discounted."""


@dataclass(frozen=True)
class Starved:
    """Runnable but not given the CPU: ``silent`` seconds without a heartbeat, of which the
    group waited ``waited`` on a run queue. Not a failure."""

    silent: float
    waited: float


@dataclass(frozen=True)
class Frozen:
    """Failed: silent past the limit while able to run (``why`` says what the kernel shows)."""

    silent: float
    why: str


@dataclass(frozen=True)
class HoldingGil:
    """Failed: the process used ``cpu`` seconds of CPU while silent (``charged`` seconds of
    the silence are not excused) but sent nothing: a call that holds the GIL, so its
    heartbeat thread cannot run."""

    silent: float
    charged: float
    cpu: float


Verdict = Alive | Starved | Frozen | HoldingGil


def waited_between(before: ProcSample, now: ProcSample) -> float:
    """How long the group waited for a CPU from ``before`` to ``now`` (two consecutive looks):
    the largest wait of one of its threads (a thread born in between counts from zero).

    The kernel adds a wait to a thread's count only when the wait ends, so a thread still
    on the run queue (throttled by a CPU quota, or behind a higher priority) shows none
    yet: a thread runnable at both looks and never put on a CPU in between waited for all
    the time it did not run. Sum it over consecutive looks: a long wait is seen piecewise.
    """
    window = now.at - before.at
    longest = 0.0
    for tid, waited in now.waited.items():
        grew = waited - before.waited.get(tid, 0.0)
        if (now.states.get(tid) == "R" and before.states.get(tid) == "R" and tid in before.ran
                and now.slices.get(tid) == before.slices.get(tid)):
            grew = max(grew, window - (now.ran.get(tid, 0.0) - before.ran[tid]))
        longest = max(longest, grew)
    return min(longest, window)


def judge(*, silent: float, limit: float, stalled: float, waited: float, before: ProcSample | None,
          now: ProcSample | None) -> Verdict:
    """The verdict on one group.

    Args:
        silent: seconds since the group's last heartbeat was sent.
        limit: the liveness limit, seconds.
        stalled: seconds of that silence in which the supervisor itself did not run.
        waited: seconds of it the group waited for a CPU (:func:`waited_between`, summed over
            the looks since ``before``).
        before: the group's process as sampled at (or just before) its last heartbeat.
        now: the group's process as sampled now; None where ``/proc`` does not say.
    """
    excused = max(0.0, stalled)
    if silent - excused <= limit:
        return Alive()
    if now is not None and now.stopped:
        return Frozen(silent, "stopped (SIGSTOP, or held by a debugger)")
    if now is None or before is None or now.at <= before.at:
        return Frozen(silent, "the kernel's view is not available, so the heartbeats decide")
    window = now.at - before.at
    waited = min(max(0.0, waited), window, silent)
    # The group's wait and the supervisor's stall may be the same moment (the machine
    # stalled): excuse the larger, never their sum.
    excused = max(excused, waited)
    charged = silent - excused
    # The first look may predate the last heartbeat: count its CPU time pro rata.
    cpu = max(0.0, now.cpu - before.cpu) * min(1.0, silent / window)
    if cpu >= BUSY_SHARE * limit:
        return HoldingGil(silent, charged, cpu)
    if charged <= limit:
        if silent > STARVATION_BOUND * limit:
            return Frozen(silent, f"starved past the bound ({STARVATION_BOUND:g} x the limit)")
        return Starved(silent, waited)
    return Frozen(silent, f"asleep: {cpu:.2f} s of CPU and {waited:.2f} s waiting for one in the "
                          f"{window:.1f} s looked at (a deadlock, or a call that blocks holding the GIL)")


class StallLog:
    """When the supervisor's watching thread did not run: episodes ``(start, end)`` on the
    ``time.monotonic()`` clock, kept for ``horizon`` seconds."""

    def __init__(self, horizon: float, least: float = 0.01) -> None:
        self.horizon = horizon
        self.least = least  # shorter stalls are the ordinary cost of waking up
        self.episodes: deque[tuple[float, float]] = deque()
        self.count = 0
        self.longest = 0.0

    def add(self, end: float, length: float) -> None:
        """The thread did not run for ``length`` seconds up to ``end``."""
        if length >= self.least:
            self.episodes.append((end - length, end))
            self.count += 1
            self.longest = max(self.longest, length)
        while self.episodes and self.episodes[0][1] < end - self.horizon:
            self.episodes.popleft()

    def within(self, start: float, end: float) -> float:
        """Seconds of stall between ``start`` and ``end``."""
        return overlap(self.episodes, start, end)


def overlap(episodes: Sequence[tuple[float, float]] | deque[tuple[float, float]], start: float,
            end: float) -> float:
    """The total length of ``episodes`` (each ``(start, end)``, in order, not overlapping)
    that falls between ``start`` and ``end``."""
    return sum(max(0.0, min(b, end) - max(a, start)) for a, b in episodes)


def stall(*, expected: float | None, woke: float, queued: float | None, away: float = 0.0) -> float:
    """How long the watching thread was held up in one turn of its loop: how late it woke
    against the latest it asked to (``expected``; None when it did not wait), the growth of
    its own run-queue wait (``queued``), or the time it spent away from the loop since the
    last turn (``away``: handling events, or stopped), whichever is largest."""
    late = 0.0 if expected is None else max(0.0, woke - expected)
    return max(late, queued or 0.0, away)
