"""Where the liveness rule's samples come from, for the process runner.

:class:`LivenessWatch` keeps what :func:`.liveness.judge` needs: when the
supervisor's own watching loop was held up (how late it woke against
CLOCK_MONOTONIC, and its thread's run-queue wait), a sample of every group's
process from ``/proc`` taken at or just before its last heartbeat, and the
starvation episodes it has seen, which it turns into notes for the run report.
It also raises the watching thread above ordinary work while the run lasts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .._isolation import procstat
from .._isolation.procstat import ProcSample
from .._isolation.watchdog import prioritise_watcher
from .liveness import STARVATION_BOUND, Alive, StallLog, Starved, Verdict, judge, stall, waited_between

__all__ = ["LivenessWatch", "SAMPLE_EVERY"]

SAMPLE_EVERY = 0.25  # seconds between two looks at every group's process (its heartbeat period)


@dataclass
class _Looks:
    """A group's process: the look at (or just before) its last heartbeat, the latest look,
    and how long it waited for a CPU between the two."""

    anchor: ProcSample
    latest: ProcSample
    waited: float = 0.0

    def add(self, looked: ProcSample) -> None:
        self.waited += waited_between(self.latest, looked)
        self.latest = looked


@dataclass
class _Episode:
    """One group starved: since when, the longest silence and wait seen, and by whom."""

    since: float
    silent: float
    waited: float
    by: str


class LivenessWatch:
    """Samples for the liveness rule (see the module docstring).

    Args:
        limit: the liveness limit, seconds.
    """

    def __init__(self, limit: float) -> None:
        self.limit = limit
        self.stalls = StallLog(horizon=(STARVATION_BOUND + 1) * limit, least=0.05)
        self.looks: dict[str, _Looks] = {}
        self.episodes: dict[str, _Episode] = {}
        self.starved_total: dict[str, float] = {}
        self.scheduling = ""
        self._restore: Callable[[], None] | None = None
        self._last_delay: float | None = None
        self._last_turn: float | None = None
        self._next_sample = 0.0

    # ---- the watching thread ---------------------------------------------------------------
    def begin(self) -> None:
        """Raise the calling thread (the watching loop) once; :meth:`end` undoes it."""
        if self._restore is None:
            self.scheduling, self._restore = prioritise_watcher()

    def end(self) -> None:
        restore, self._restore = self._restore, None
        if restore is not None:
            restore()

    def turn(self, started: float, expected: float | None, woke: float) -> None:
        """One turn of the watching loop began at ``started`` and ended its wait at ``woke``;
        it asked to wake at ``expected`` at the latest (None: it did not wait)."""
        delay = procstat.own_run_delay()
        queued = None if delay is None or self._last_delay is None else delay - self._last_delay
        away = 0.0 if self._last_turn is None else started - self._last_turn
        self._last_delay, self._last_turn = delay, woke
        self.stalls.add(woke, stall(expected=expected, woke=woke, queued=queued, away=away))

    # ---- the groups ------------------------------------------------------------------------
    def sample(self, groups: dict[str, tuple[int, float]], now: float) -> None:
        """Every ``SAMPLE_EVERY``: look at each group's process (``name -> (pid, last heard)``)
        and keep the look as its anchor when it was taken at or before the last heartbeat."""
        if now < self._next_sample:
            return
        self._next_sample = now + SAMPLE_EVERY
        for name, (pid, heard) in groups.items():
            self._look(name, pid, heard)

    def _look(self, name: str, pid: int, heard: float) -> ProcSample | None:
        looked = procstat.sample(pid)
        if looked is None:
            return None
        looks = self.looks.get(name)
        if looks is None or looked.at <= heard:
            self.looks[name] = _Looks(anchor=looked, latest=looked)
        else:
            looks.add(looked)
        return looked

    def check(self, name: str, pid: int, heard: float, now: float) -> tuple[Verdict, list[str]]:
        """The verdict on group ``name`` last heard at ``heard``, and notes for the report."""
        silent = now - heard
        stalled = self.stalls.within(heard, now)
        if silent - stalled <= self.limit:
            return Alive(), self.over(name)
        looked = self._look(name, pid, heard)
        looks = self.looks.get(name)
        verdict = judge(silent=silent, limit=self.limit, stalled=stalled, waited=looks.waited if looks else 0.0,
                        before=looks.anchor if looks else None, now=looked)
        if not isinstance(verdict, Starved):
            return verdict, []
        episode = self.episodes.get(name)
        if episode is None:
            cpus = looks.anchor.cpus if looks else frozenset()
            named = procstat.rivals(cpus, exclude=pid)
            by = procstat.machine_load() + (f"; runnable there: {', '.join(named)}" if named else "")
            quota = procstat.cpu_quota(pid)
            if quota:
                by = f"{quota}; {by}"
            episode = self.episodes[name] = _Episode(since=heard, silent=0.0, waited=0.0, by=by)
        episode.silent = max(episode.silent, verdict.silent)
        episode.waited = max(episode.waited, verdict.waited)
        return verdict, []

    def over(self, name: str) -> list[str]:
        """End group ``name``'s starvation episode, if one is open: the note that reports it."""
        episode = self.episodes.pop(name, None)
        if episode is None:
            return []
        self.starved_total[name] = self.starved_total.get(name, 0.0) + episode.silent
        text = (f"starved, not failed: no heartbeat for {episode.silent:.1f} s (the limit is {self.limit:g} s) "
                f"while runnable, {episode.waited:.1f} s of it waiting for a CPU; by {episode.by}")
        return [text]

    def forget(self, name: str) -> list[str]:
        """Group ``name``'s process is gone or replaced: drop its samples, report an open episode."""
        self.looks.pop(name, None)
        return self.over(name)

    def notes(self) -> list[str]:
        """Run-wide facts: where the watching thread ran, and how often it was held up."""
        text = (f"liveness: the supervisor's watching thread ran at {self.scheduling or 'its own scheduling'}; "
                f"a group is failed after {self.limit:g} s without a heartbeat in which it could run "
                f"(starvation is reported, up to {STARVATION_BOUND * self.limit:g} s)")
        if self.stalls.count:
            text += (f"; the supervisor itself was held up {self.stalls.count} times (longest "
                     f"{self.stalls.longest:.2f} s), not counted against the groups")
        return [text]
