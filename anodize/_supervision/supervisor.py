"""The supervision core: one implementation of failure policy, run state, status and reports.

A *runner* (threads for ``inproc``, processes for ``process``) starts groups,
carries the supervisor's word to them and turns what happens into
:class:`~.events.Event` values; :class:`Supervisor` decides everything else, the same way
for every transport:

- a role that fails has every other group told at once (its peers get
  ``PeerFailedError`` instead of waiting), then its group's policy applies:
  ``stop`` (the rest runs on), ``stop-system`` (every group stops) or
  ``restart``; a restart starts the group again from its initial states on fresh
  channels, together with every group connected to it that also restarts (a
  session cannot resume with a role that forgot where it was), at most
  ``max_restarts`` times;
- the timeout counts from "go" (every group ready), then every group is asked
  to stop and, ``grace`` seconds later, ended;
- Ctrl-C stops the run the same way, and the report says it was interrupted;
- so does the caller's ``stop_when``, when it gives a reason (a mission done).
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum

from .._session.logs import LogEntry
from ..errors import RoleError
from .events import Counts, Event, GroupExited, GroupFailed, Logged, Note, Ready, RoleEnded
from .group import FailurePolicy, Group
from .hostview import HELLO_EVERY, HostView
from .logsummary import LogSummary
from .report import GroupReport, GroupState, GroupStatus, RoleReport, RoleStatus, RunReport
from .roles import describe_error
from .runner import Elsewhere, Runner
from .words import Decision, HelloWord, RestartWord, StopWord, Word

__all__ = ["Supervisor", "RunState", "window_rates"]

TICK = 0.1           # seconds between two looks at the clock when nothing happens
STATUS_EVERY = 0.5   # seconds between two on_status calls
RATE_WINDOW = 1.0    # seconds per window of the reported message rates
KILL_BOUND = 5.0     # seconds an ended group has to be gone before the supervisor stops waiting for it


class RunState(StrEnum):
    """Where the run as a whole is."""

    STARTING = "starting"  # groups starting; the timeout has not begun
    RUNNING = "running"
    STOPPING = "stopping"  # every group was asked to stop
    ENDED = "ended"


@dataclass
class _Remote:
    """What this host knows of a group that runs on another."""

    group: Group
    incarnation: int = 0
    restarts: int = 0


# ---- the core --------------------------------------------------------------------------------
class _Why(StrEnum):
    """Why the supervisor ended or stopped an incarnation (empty: it has not)."""

    NONE = ""
    STOP = "stop"
    RESTART = "restart"
    FAILED = "failed"


@dataclass
class _GroupRecord:
    """One group across its incarnations."""

    group: Group
    incarnation: int = -1
    state: GroupState = GroupState.STARTING
    ready: bool = False
    ended: bool = True
    why: _Why = _Why.NONE
    killed: bool = False  # the supervisor ended it: its death is no failure of its own
    killed_at: float = 0.0
    stop_by: float | None = None  # asked to stop alone (the run moved on without it): ended then
    error: BaseException | None = None
    reports: dict[str, RoleReport] = field(default_factory=dict)
    scheduling: str = ""
    memory_note: str = ""
    pid: int | None = None
    restarts: int = 0
    restart_as: int | None = None  # the incarnation a restart decided across hosts gives it
    failures: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    memory: int | None = None
    peak: int | None = None
    sent: dict[str, int] = field(default_factory=dict)        # all incarnations
    received: dict[str, int] = field(default_factory=dict)
    sent_before: dict[str, int] = field(default_factory=dict)  # earlier incarnations' totals
    checked: dict[str, int] = field(default_factory=dict)  # per constrained interaction, all incarnations
    checked_before: dict[str, int] = field(default_factory=dict)
    closest: dict[str, float] = field(default_factory=dict)
    timeouts: dict[str, int] = field(default_factory=dict)
    timeouts_before: dict[str, int] = field(default_factory=dict)
    received_before: dict[str, int] = field(default_factory=dict)
    high_water: dict[str, int] = field(default_factory=dict)  # all incarnations: the most waiting
    # (time, messages sent so far), in stretches during which every role of the group ran
    stretches: list[list[tuple[float, int]]] = field(default_factory=list)
    steady: bool = False  # in such a stretch now
    steady_since: float = 0.0


class Supervisor:
    """Runs a system's groups through a :class:`Runner`; :meth:`run` returns the report."""

    def __init__(self, protocol: str, roles: Sequence[str], groups: dict[str, Group],
                 channels: Sequence[tuple[str, str]], runner: Runner, timeout: float | None,
                 grace: float, on_status: Callable[[dict[str, GroupStatus]], None] | None,
                 elsewhere: Elsewhere | None = None, stop_when: Callable[[], str | None] | None = None,
                 on_log: Callable[[Sequence[LogEntry]], None] | None = None) -> None:
        self.protocol = protocol
        self.roles = tuple(roles)
        self.channels = tuple(channels)
        self.elsewhere = elsewhere
        self.runner = runner
        self.timeout = timeout
        self.grace = grace
        self.on_status = on_status
        self.stop_when = stop_when
        self.on_log = on_log  # handed the roles' log records as they come (the terminal, taps)
        self.logs = LogSummary()
        self.records = {name: _GroupRecord(group) for name, group in groups.items()}
        everyone = groups if elsewhere is None else elsewhere.groups
        self.group_of = {role: g.name for g in everyone.values() for role in g.roles}
        self.remote = {name: _Remote(g) for name, g in everyone.items() if name not in groups}
        self.state = RunState.STARTING
        self.started = time.monotonic()
        self.went: float | None = None
        self.stop_since = 0.0
        self.interrupted = False
        self.notes: list[str] = []
        self.stop_why = ""  # why every group stops, once they do
        self.decisions: list[Decision] = []  # every restart across hosts decided or heard of
        self.view = (HostView(elsewhere.link.host, os.getpid(), elsewhere.link.supervisor, elsewhere.lost_after)
                     if elsewhere is not None else None)
        self.next_hello = 0.0
        self.hellos_said = 0  # they are numbered (HelloWord.number): a gap where they are heard is a cut

    # ---- the run ---------------------------------------------------------------------------
    def run(self) -> RunReport:
        """Start every group, supervise to the end, and report (also after Ctrl-C)."""
        try:
            self._start(list(self.records))
            next_status = time.monotonic() + STATUS_EVERY
            while self._live():
                try:
                    self._step()
                    if time.monotonic() >= next_status:
                        self._ask_stop_when()
                        if self.on_status is not None:
                            self.on_status(self.statuses())
                        next_status = time.monotonic() + STATUS_EVERY
                except KeyboardInterrupt:
                    if self.interrupted:  # a second Ctrl-C: no more grace
                        for name in self._running():
                            self.runner.kill(name)
                    self.interrupted = True
                    self._stop_all("interrupted (Ctrl-C)")
        finally:
            self.state = RunState.ENDED
            try:
                self._farewell()
            finally:
                self.notes[:0] = self.runner.notes()
                self.runner.close()
        report = self.report()
        if self.on_status is not None:
            self.on_status(self.statuses())
        return report

    def _step(self) -> None:
        if (self.timeout is not None and self.went is not None and self.state is RunState.RUNNING
                and time.monotonic() >= self.went + self.timeout):
            self._stop_all("the timeout passed")
        for event in self.runner.events(TICK):
            self._handle(event)
        if self.elsewhere is not None:
            for word in self.elsewhere.link.words():
                self._heard(word)
            self._look_around()
        if self.state is RunState.STOPPING and time.monotonic() - self.stop_since > self.grace:
            for name in self._running():
                self._end(name, _Why.STOP)
        for name, record in self.records.items():  # stopped alone: ended after the same grace
            if record.stop_by is not None and not record.ended and time.monotonic() > record.stop_by:
                self._end(name, _Why.STOP)
        for record in self.records.values():  # every wait for a group is bounded, the last one too
            if record.killed and not record.ended and time.monotonic() - record.killed_at > KILL_BOUND:
                self._exited(record, f"it did not end within {KILL_BOUND:g} s of being killed; "
                                     "the run stopped waiting for it")

    def _ask_stop_when(self) -> None:
        """Stop every group once the caller's ``stop_when`` gives a reason (asked only while running)."""
        if self.stop_when is None or self.state is not RunState.RUNNING:
            return
        try:
            why = self.stop_when()
        except Exception as error:  # the caller's code: its failure ends neither supervision nor the run
            self.notes.append(f"stop_when raised {type(error).__name__}: {error}; it is asked no more, and the "
                              "run goes on to its timeout")
            self.stop_when = None
            return
        if why:
            self._stop_all(str(why))

    def _live(self) -> bool:
        return any(not r.ended for r in self.records.values())

    def _running(self) -> list[str]:
        return [name for name, r in self.records.items() if not r.ended]

    # ---- starting --------------------------------------------------------------------------
    def _start(self, names: list[str]) -> None:
        # One incarnation number per batch, above each member's last (a runner names the
        # batch's channels by it, and its events carry it): the number a restart decided
        # across hosts gave the batch, if any.
        chosen = [r.restart_as for r in (self.records[n] for n in names) if r.restart_as is not None]
        incarnation = max(chosen, default=max(self.records[n].incarnation + 1 for n in names))
        for name in names:
            record = self.records[name]
            record.incarnation = incarnation
            record.restart_as = None
            record.state = GroupState.STARTING if incarnation == 0 else GroupState.RESTARTING
            record.ready = record.ended = False
            record.why, record.killed, record.error, record.reports = _Why.NONE, False, None, {}
            record.killed_at = 0.0
            record.steady = False
        self.runner.start(names, incarnation)

    def _maybe_go(self) -> None:
        """Once no group is still starting, let the ready ones go together."""
        if any(not r.ended and not r.ready for r in self.records.values()):
            return
        for name, record in self.records.items():
            if record.ready and record.state in (GroupState.STARTING, GroupState.RESTARTING):
                record.state = GroupState.RUNNING
                record.steady = True
                record.steady_since = time.monotonic()
                record.stretches.append([])
                self.runner.go(name)
                if self.went is None:
                    self.went = time.monotonic()
                    self.state = RunState.RUNNING
                    if self.timeout is not None:
                        self.runner.bound(self.timeout + self.grace)

    # ---- events ----------------------------------------------------------------------------
    def _handle(self, event: Event) -> None:
        if isinstance(event, Logged):
            self._logged(event)
            return
        record = self.records.get(event.group)
        if record is None:
            return
        if isinstance(event, Note):
            record.notes.append(event.text)
            return
        if event.incarnation != record.incarnation or record.ended:
            return  # a late word from an incarnation already ended (e.g. an abandoned thread)
        match event:
            case Ready():
                record.ready = True
                record.scheduling = event.scheduling
                record.memory_note = event.memory_note
                record.pid = event.pid
                self._maybe_go()
            case Counts():
                self._counts(record, event)
            case RoleEnded():
                self._role_ended(record, event.report)
            case GroupFailed():
                if not record.killed:
                    self._group_failed(record, event.error)
            case GroupExited():
                self._exited(record, event.unreported, event.details)

    def _logged(self, event: Logged) -> None:
        """Count the roles' records for the report and hand them on (a failing receiver is told no more)."""
        self.logs.add(event.entries, event.dropped)
        if self.on_log is None or not event.entries:
            return
        try:
            self.on_log(event.entries)
        except Exception as error:  # the caller's code: its failure ends neither supervision nor the run
            self.notes.append(f"on_log raised {type(error).__name__}: {error}; it is handed no more records")
            self.on_log = None

    def _counts(self, record: _GroupRecord, counts: Counts) -> None:
        if counts.memory is not None:
            record.memory = counts.memory
        if counts.peak is not None:
            record.peak = max(record.peak or 0, counts.peak)
        if counts.sent is None or counts.received is None:
            return
        for channel, n in counts.sent.items():
            record.sent[channel] = record.sent_before.get(channel, 0) + n
        for channel, n in counts.received.items():
            record.received[channel] = record.received_before.get(channel, 0) + n
        for channel, n in (counts.waiting or {}).items():
            record.high_water[channel] = max(record.high_water.get(channel, 0), n)
        for key, n in (counts.checked or {}).items():
            record.checked[key] = record.checked_before.get(key, 0) + n
        for key, margin in (counts.closest or {}).items():
            record.closest[key] = min(record.closest.get(key, margin), margin)
        for key, n in (counts.timeouts or {}).items():
            record.timeouts[key] = record.timeouts_before.get(key, 0) + n
        stretch = record.stretches[-1] if record.steady and self.state is RunState.RUNNING else None
        if stretch is not None and counts.at >= record.steady_since:  # not counted before "go"
            stretch.append((counts.at, sum(record.sent.values())))

    def _role_ended(self, record: _GroupRecord, report: RoleReport) -> None:
        record.scheduling = record.scheduling or report.scheduling  # threads apply it per role
        if not report.scheduling:  # a group process applies it once, to all its roles
            report = dataclasses.replace(report, scheduling=record.scheduling)
        record.reports[report.name] = report
        record.steady = False  # a group with a role gone no longer runs at its rate
        if report.status is RoleStatus.FAILED:
            self._broadcast_failure(record.group.name, {report.name: describe_error(report.error)})
            self._apply_policy(record, f"role {report.name}: {describe_error(report.error)}",
                               split=_split_brain(report.error))

    def _group_failed(self, record: _GroupRecord, error: BaseException) -> None:
        """The whole group failed: every unreported role with it, and it is ended."""
        if record.error is not None:
            return
        record.error = error
        record.steady = False
        missing = [r for r in record.group.roles if r not in record.reports]
        for role in missing:
            record.reports[role] = RoleReport(name=role, group=record.group.name, status=RoleStatus.FAILED,
                                              error=error, scheduling=record.scheduling)
        self._broadcast_failure(record.group.name, dict.fromkeys(missing, describe_error(error)))
        self._apply_policy(record, describe_error(error), whole_group=True, split=_split_brain(error))

    def _exited(self, record: _GroupRecord, unreported: str, details: dict[str, str] | None = None) -> None:
        record.ended = True
        record.steady = False
        missing = [r for r in record.group.roles if r not in record.reports]
        if missing and record.why is _Why.NONE and record.error is None:
            # Ended on its own before its roles reported: that is a failure of the group.
            self._group_failed(record, RoleError("GroupEnded", unreported or
                                                 f"group {record.group.name} ended before its roles reported"))
        for role in [r for r in record.group.roles if r not in record.reports]:
            stopped = record.why is _Why.STOP and record.error is None
            record.reports[role] = RoleReport(
                name=role, group=record.group.name,
                status=RoleStatus.STOPPED if stopped else RoleStatus.FAILED,
                error=None if stopped else record.error, scheduling=record.scheduling,
                detail=(details or {}).get(role, unreported) if stopped else "")
        record.state = self._final_state(record)
        if record.why is _Why.RESTART:
            self._restart_when_ready()
        self._maybe_go()

    @staticmethod
    def _final_state(record: _GroupRecord) -> GroupState:
        statuses = {r.status for r in record.reports.values()}
        if RoleStatus.FAILED in statuses or record.error is not None:
            return GroupState.FAILED
        return GroupState.STOPPED if RoleStatus.STOPPED in statuses else GroupState.DONE

    # ---- failure policy --------------------------------------------------------------------
    def _broadcast_failure(self, group: str, causes: dict[str, str]) -> None:
        for name, other in self.records.items():
            if name != group and not other.ended:
                for role, cause in causes.items():
                    self.runner.tell_failed(name, role, cause)

    def _apply_policy(self, record: _GroupRecord, what: str, whole_group: bool = False, split: bool = False) -> None:
        record.failures.append(f"{time.monotonic() - self.started:.2f} s: {what}")
        if self.state is RunState.STOPPING:
            if whole_group:
                self._end(record.group.name, _Why.FAILED)
            return
        if record.why is _Why.RESTART:
            return  # a restart (of a set it is in) is under way: this failure is that set's too
        policy = record.group.on_failure
        if split:  # as the supervisors do (split brain): a restart would meet both claimants again
            self._stop_all(f"group {record.group.name} failed at its start barrier, where two endpoints claim one "
                           "peer group (split brain): every group of the run stops")
            if whole_group:
                self._end(record.group.name, _Why.FAILED)
        elif policy is FailurePolicy.STOP_SYSTEM:
            self._stop_all(f"group {record.group.name} failed and its policy is stop-system")
            if whole_group:
                self._end(record.group.name, _Why.FAILED)
        elif policy is FailurePolicy.RESTART and record.restarts < record.group.max_restarts:
            members = self._restart_set(record.group.name)
            incarnation = None
            if self.elsewhere is not None:  # the groups of the set elsewhere restart as the same incarnation
                incarnation = 1 + max([r.incarnation if r.restart_as is None else r.restart_as
                                       for r in self.records.values()] + [r.incarnation for r in self.remote.values()])
                self.decisions.append(Decision(incarnation, tuple(members), what, self.elsewhere.link.host))
                self.elsewhere.link.say(RestartWord(self.elsewhere.link.host, tuple(members), incarnation, what))
                self._restarted_elsewhere(members, incarnation)
            for name in members:
                if name in self.records:
                    self._mark_restart(name, incarnation)
            self._restart_when_ready()
        elif whole_group:
            self._end(record.group.name, _Why.FAILED)  # stopped as a whole: all its threads, all its memory

    def _mark_restart(self, name: str, incarnation: int | None) -> None:
        record = self.records[name]
        record.restart_as = incarnation
        if record.ended:
            record.why = _Why.RESTART
        else:
            self._end(name, _Why.RESTART)

    def _restart_set(self, name: str) -> list[str]:
        """``name`` and the groups connected to it through channels that also restart (on any host)."""
        channels = self.channels if self.elsewhere is None else self.elsewhere.channels
        found, todo = {name}, [name]
        while todo:
            current = todo.pop()
            for sender, receiver in channels:
                for a, b in ((sender, receiver), (receiver, sender)):
                    ga, gb = self.group_of[a], self.group_of[b]
                    other = self.records.get(gb) or self.remote[gb]
                    if (ga == current and gb not in found and other.group.on_failure is FailurePolicy.RESTART
                            and other.restarts < other.group.max_restarts):
                        found.add(gb)
                        todo.append(gb)
        return sorted(found)

    # ---- what other hosts said -------------------------------------------------------------
    def _heard(self, word: Word) -> None:
        if isinstance(word, HelloWord):
            self._hello(word)
            return
        if isinstance(word, StopWord):
            self._stop_all(f"{word.why} (on host {word.host})", tell=False)
            return
        if all(d.incarnation != word.incarnation for d in self.decisions):
            self.decisions.append(Decision(word.incarnation, word.groups, word.why, word.host))
        self._restarted_elsewhere(word.groups, word.incarnation)
        if self.state is RunState.STOPPING:
            return
        for name in word.groups:
            record = self.records.get(name)
            if record is None or max(record.incarnation, record.restart_as or 0) >= word.incarnation:
                continue  # not ours, or restarted as this incarnation already (we decided it too)
            record.notes.append(f"restarted as incarnation {word.incarnation} with groups "
                                f"{', '.join(word.groups)}, decided on host {word.host}: {word.why}")
            self._mark_restart(name, word.incarnation)
        self._restart_when_ready()

    def _restarted_elsewhere(self, groups: Sequence[str], incarnation: int) -> None:
        for name in groups:
            remote = self.remote.get(name)
            if remote is not None and remote.incarnation < incarnation:
                remote.incarnation = incarnation
                remote.restarts += 1

    def _restart_when_ready(self) -> None:
        """Start the groups marked for restart once every one of them has ended."""
        marked = [n for n, r in self.records.items() if r.why is _Why.RESTART]
        if not marked or any(not self.records[n].ended for n in marked) or self.state is RunState.STOPPING:
            return
        for name in marked:
            record = self.records[name]
            record.restarts += 1
            record.sent_before = dict(record.sent)
            record.checked_before = dict(record.checked)
            record.timeouts_before = dict(record.timeouts)
            record.received_before = dict(record.received)
        self._start(marked)

    def _end(self, name: str, why: _Why) -> None:
        record = self.records[name]
        if record.why in (_Why.NONE, _Why.STOP):
            record.why = why
        if not record.ended and not record.killed:
            record.killed = True
            record.killed_at = time.monotonic()
            self.runner.kill(name)

    def _stop_all(self, why: str, tell: bool = True) -> None:
        if self.state is RunState.STOPPING:
            return
        if tell and self.elsewhere is not None:
            self.elsewhere.link.say(StopWord(self.elsewhere.link.host, why))
        self.state = RunState.STOPPING
        self.stop_why = why
        self.stop_since = time.monotonic()
        self.next_hello = 0.0  # and in a hello at once: one cut off when the word was said may be back
        self.notes.append(f"stopping every group: {why}")
        for name, record in self.records.items():
            if record.why is _Why.RESTART and record.ended:
                record.why = _Why.STOP  # a restart still pending will not happen now
            if not record.ended:
                if record.why is _Why.NONE:
                    record.why = _Why.STOP
                self.runner.stop(name)

    # ---- the other supervisors: hellos, split brain, hosts lost and back -------------------
    def _hello_word(self) -> HelloWord:
        assert self.elsewhere is not None and self.view is not None
        state = {RunState.STOPPING: "stopping", RunState.ENDED: "ended"}.get(self.state, "running")
        self.hellos_said += 1
        return HelloWord(self.elsewhere.link.host, os.getpid(), {n: r.incarnation for n, r in self.records.items()},
                         state, self.stop_why, tuple(self.decisions),
                         {host: dict(groups) for host, groups in self.view.gone.items()},
                         number=self.hellos_said - 1, supervisor=self.elsewhere.link.supervisor)

    def _look_around(self) -> None:
        """Say hello when it is time; notice the supervisors lost since the last look."""
        assert self.elsewhere is not None and self.view is not None
        now = time.monotonic()
        for hello in self.view.look(now):
            self.notes.append(f"lost sight of host {hello.host} at {now - self.started:.1f} s (no word from its "
                              f"supervisor for {self.view.lost_after:g} s): the run moves on without it")
        if now >= self.next_hello:
            self.next_hello = now + HELLO_EVERY
            self.elsewhere.link.say(self._hello_word())

    def _hello(self, hello: HelloWord) -> None:
        """What another supervisor's hello tells: a second claimant of a group (split brain),
        restarts and a stop it missed while it was cut off, or that it moved on without us."""
        assert self.elsewhere is not None and self.view is not None
        now = time.monotonic()
        if self.view.stale(hello):  # a repeat or a replay of one heard already
            return
        first = hello.supervisor not in self.view.peers  # never heard before: it could not be lost here
        back = self.view.hear(hello, now)
        if back is not None:
            self.notes.append(back)
        split = self.view.split(hello, {name: r.incarnation for name, r in self.records.items()})
        if split is not None:
            text, shared = split
            for name in shared & set(self.records):
                record = self.records[name]
                if record.error is None and not record.ended:
                    record.error = RoleError("SplitBrain", text)
            self._stop_all(text)
            return
        for decision in hello.restarts:  # heard again: a restart said while we were cut off is not lost
            self._heard(RestartWord(decision.host, decision.groups, decision.incarnation, decision.why))
        if hello.why and hello.state != "running":
            self._stop_all(f"{hello.why} (on host {hello.host})", tell=False)
        ours = hello.gone.get(self.elsewhere.link.host)
        # A cut (not just a supervisor slow to speak): we lost it too, or hellos of it were lost on
        # the way lately, or we had never heard it at all (cut off before its first hello reached
        # us: nothing here to lose, yet it lost us; a hello said before the cut and delivered after
        # it, as Zenoh may, leaves a gap in the numbers before this one).
        if ours and (first or hello.host in self.view.gone or self.view.missed_lately(hello.supervisor, now)):
            self._moved_on(hello, ours)

    def _moved_on(self, hello: HelloWord, ours: dict[str, int]) -> None:
        """``hello``'s supervisor lost sight of this host and moved on: our groups with channels to
        its groups, as they were then (not restarted since, nor to be), stop (their sessions are over)."""
        assert self.elsewhere is not None
        theirs = set(hello.groups)
        stopped = []
        for name, incarnation in ours.items():
            record = self.records.get(name)
            if (record is None or record.ended or record.incarnation > incarnation or record.restart_as is not None
                    or record.why is not _Why.NONE or self.state is RunState.STOPPING
                    or not any({self.group_of[a], self.group_of[b]} & theirs and name in (self.group_of[a],
                                                                                          self.group_of[b])
                               for a, b in self.elsewhere.channels)):
                continue
            record.notes.append(f"stopped: host {hello.host} lost sight of this host and moved on without it")
            record.why = _Why.STOP
            record.stop_by = time.monotonic() + self.grace
            self.runner.stop(name)
            stopped.append(name)
        if stopped:
            self.notes.append(f"host {hello.host} lost sight of this host (cut off?) and moved on without it: "
                              f"stopping {', '.join(stopped)}, whose sessions with groups there are over")

    def _farewell(self) -> None:
        """Tell the others this supervisor leaves. One that stopped the run first waits (up to
        ``linger`` seconds) until every other supervisor has said it stops too: one cut off when
        the stop was said hears it if it comes back meanwhile."""
        if self.elsewhere is None or self.view is None:
            return
        link, view = self.elsewhere.link, self.view
        waited_for = view.unreached() if self.stop_why else []
        deadline = time.monotonic() + self.elsewhere.linger
        while self.stop_why and view.unreached() and time.monotonic() < deadline:
            now = time.monotonic()
            if now >= self.next_hello:
                self.next_hello = now + HELLO_EVERY
                link.say(self._hello_word())
            for word in link.words():
                if isinstance(word, HelloWord):
                    back = view.hear(word, time.monotonic())
                    if back is not None:
                        self.notes.append(back)
            view.look(time.monotonic())
            time.sleep(TICK)
        unreached = view.unreached() if self.stop_why else []
        if unreached:
            self.notes.append(f"the run stopped while host{'s' if len(unreached) > 1 else ''} {', '.join(unreached)} "
                              f"did not answer; {'they' if len(unreached) > 1 else 'it'} did not say "
                              f"{'they' if len(unreached) > 1 else 'it'} stopped within {self.elsewhere.linger:g} s")
        elif waited_for and any(h in view.gone for h in waited_for):
            self.notes.append(f"host{'s' if len(waited_for) > 1 else ''} {', '.join(waited_for)}, cut off when the "
                              "run stopped, came back and heard so")
        # Back from a cut, the others may not have found this host again yet (the network's own
        # discovery): say goodbye for a while, not once, so that a host waiting to hear it stops, does.
        until = time.monotonic() + (view.lost_after if view.gone else 0.0)
        while True:
            link.say(self._hello_word())
            if time.monotonic() >= until:
                break
            time.sleep(HELLO_EVERY)

    # ---- reporting -------------------------------------------------------------------------
    def statuses(self) -> dict[str, GroupStatus]:
        """A live snapshot per group."""
        return {name: GroupStatus(
            name=name, state=r.state, pid=r.pid if not r.ended else None, memory=r.memory,
            messages=sum(r.sent.values()), received=sum(r.received.values()),
            rate_hz=_last_rate(r.stretches[-1] if r.steady else []), restarts=r.restarts, note="; ".join(r.notes),
            roles={role: str(r.reports[role].status) if role in r.reports else str(r.state) for role in r.group.roles},
            sent=dict(r.sent), high_water=dict(r.high_water), scheduling=r.scheduling)
            for name, r in self.records.items()}

    def report(self) -> RunReport:
        """The run's report: roles, groups, channels, notes."""
        roles: dict[str, RoleReport] = {}
        groups: dict[str, GroupReport] = {}
        for name, r in self.records.items():
            roles.update(r.reports)
            rates = [rate for stretch in r.stretches for rate in window_rates(stretch)]
            groups[name] = GroupReport(
                name=name, status=r.state, scheduling=r.scheduling, peak_memory=r.peak,
                memory_note=r.memory_note, notes=tuple(r.notes), memory_bound=r.group.memory,
                error=r.error, restarts=r.restarts, failures=tuple(r.failures),
                messages=sum(r.sent.values()), received=sum(r.received.values()),
                rate_hz=statistics.median(rates) if rates else None,
                rate_min_hz=min(rates) if rates else None, pid=r.pid)
        for role in self.roles:
            roles.setdefault(role, RoleReport(name=role, group=self.group_of[role], status=RoleStatus.STOPPED))
        sent = {f"{a}->{b}": 0 for a, b in self.channels}
        received = dict(sent)
        high_water: dict[str, int] = {}
        constraints: dict[str, dict[str, float | None]] = {}
        for r in self.records.values():
            sent.update({c: n for c, n in r.sent.items() if c in sent})
            received.update({c: n for c, n in r.received.items() if c in received})
            high_water.update({c: n for c, n in r.high_water.items() if c in sent})
            constraints.update({key: {"checked": n, "closest_s": r.closest.get(key), "timeouts": r.timeouts.get(key, 0)}
                                for key, n in r.checked.items()})
        # Priority inheritance, where the runner applies it (in-process and process runners).
        inheritance = getattr(self.runner, "inheritance_report", None)
        boosts, inactive = inheritance() if inheritance is not None else ({}, [])
        return RunReport(protocol=self.protocol, roles={role: roles[role] for role in self.roles},
                         groups=groups, messages=sent, received=received, high_water=high_water,
                         constraints=dict(sorted(constraints.items())),
                         duration=time.monotonic() - self.started, transport=self.runner.transport,
                         interrupted=self.interrupted, notes=tuple(self.notes),
                         boosts={f"{waiter}->{target}": {"episodes": b.episodes, "seconds": round(b.seconds, 6)}
                                 for (waiter, target), b in boosts.items()},
                         inheritance_inactive=tuple(inactive), logs=self.logs)


def _split_brain(error: BaseException | None) -> bool:
    """Whether a group failed because two endpoints claimed one of its peers at its start barrier."""
    name = error.type_name if isinstance(error, RoleError) else type(error).__name__
    return name == "SplitBrainError"


def window_rates(samples: list[tuple[float, int]], window: float = RATE_WINDOW) -> list[float]:
    """Messages per second over consecutive windows of at least ``window`` seconds.

    ``samples`` are ``(time, messages so far)`` taken while every role of the group ran,
    so start-up, the tail after a role ended and the wait for a stop never count as a
    slow second; a stretch shorter than ``window`` gives no rate at all.
    """
    rates: list[float] = []
    if not samples:
        return rates
    start_t, start_n = samples[0]
    for t, n in samples[1:]:
        if t - start_t >= window:
            rates.append((n - start_n) / (t - start_t))
            start_t, start_n = t, n
    return rates


def _last_rate(samples: list[tuple[float, int]]) -> float | None:
    recent = [s for s in samples if samples[-1][0] - s[0] <= RATE_WINDOW] if samples else []
    if len(recent) < 2 or recent[-1][0] <= recent[0][0]:
        return None
    return (recent[-1][1] - recent[0][1]) / (recent[-1][0] - recent[0][0])
