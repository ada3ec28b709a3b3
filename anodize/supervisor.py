"""The supervisor of ``transport="process"``: the paper's primordial thread, with teeth.

It spawns one process per group (:mod:`anodize.groupproc`), wires a pipe for
every channel between roles of different groups, and then only listens: to
each group's control connection (ready, heartbeats, role reports, memory
events) and to each process's exit. It never carries protocol messages.

When a group fails it tells every other group which roles are gone (so their
peers get ``PeerFailedError`` at once) and applies the group's policy:
``stop`` (the rest runs on), ``stop-system`` (every group is stopped) or
``restart``. A restart starts the group again from its initial states on fresh
channels, together with every group it is connected to that also restarts
(a session cannot resume with a role that forgot where it was); peers outside
that set see the restarted roles as failed.
"""

from __future__ import annotations

import multiprocessing
import os
import secrets
import signal
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from typing import TYPE_CHECKING, Any

from sessiontypes.graph import communication_graph

from .codec import DecodeError
from .errors import MemoryBoundError, RoleError, error_from_data
from .group import Group, reference_of
from .groupproc import EXIT_MEMORY, GroupSpec, control_recv, control_send, group_main
from .memory import CGROUP_SLACK, Cgroup, make_cgroup, remove_stale_cgroups, rss
from .report import GroupReport, GroupStatus, RoleReport, RunReport, Status
from .roles import describe_error
from .shm import remove_run_segments, remove_stale_segments
from .watchdog import Watchdog, rt_throttling

if TYPE_CHECKING:
    from .system import System

__all__ = ["run_processes", "WATCHDOG_LIMIT"]

WATCHDOG_LIMIT = 0.5  # seconds a FIFO group may keep a CPU busy before it is demoted (< RT throttling's 0.95 s)
_TICK = 0.1
_STATUS_EVERY = 0.5
_START_TIMEOUT = 60.0  # seconds for a group's process to import its roles and report ready


@dataclass
class _Incarnation:
    """One group's current process and what it has said."""

    group: Group
    number: int
    process: Any = None
    control: Connection | None = None
    state: str = "starting"  # starting | ready | running | ended
    pid: int | None = None
    scheduling: str = ""
    baseline: int = 0
    memory_note: str = ""
    reports: dict[str, RoleReport] = field(default_factory=dict)
    error: BaseException | None = None
    killed_on_purpose: str = ""  # "stop" | "restart" | "failed" when the supervisor ended it
    cgroup: Cgroup | None = None
    started_at: float = field(default_factory=time.monotonic)
    deaf: bool = False  # its end of the control connection is closed for our messages


@dataclass
class _History:
    """What outlives a group's incarnations."""

    restarts: int = 0
    failures: list[str] = field(default_factory=list)
    peak: int = 0
    memory: int | None = None
    sent: dict[str, int] = field(default_factory=dict)  # "A->B" -> count, all incarnations
    sent_before: dict[str, int] = field(default_factory=dict)  # earlier incarnations' totals
    samples: list[tuple[float, int]] = field(default_factory=list)  # (time, messages sent)
    notes: list[str] = field(default_factory=list)


def run_processes(system: System, timeout: float | None, grace: float,
                  on_status: Callable[[dict[str, GroupStatus]], None] | None) -> RunReport:
    """Run ``system`` with one OS process per group; always returns a report."""
    return _Supervisor(system, timeout, grace, on_status).run()


class _Supervisor:
    def __init__(self, system: System, timeout: float | None, grace: float,
                 on_status: Callable[[dict[str, GroupStatus]], None] | None) -> None:
        self.system = system
        self.gt = system.global_type
        self.timeout = timeout
        self.grace = grace
        self.on_status = on_status
        self.run_id = f"{os.getpid()}-{secrets.token_hex(3)}"
        self.context = multiprocessing.get_context("spawn")  # a fresh interpreter: nothing shared
        self.machines = {role: self.gt.project(role).fsm() for role in self.gt.roles}
        self.channels = tuple(communication_graph(self.gt).edges)
        self.group_of = {role: g.name for g in system.groups.values() for role in g.roles}
        self.current: dict[str, _Incarnation] = {}
        self.history = {name: _History() for name in system.groups}
        self.stopping = False
        self.notes: list[str] = []
        self.watchdog = Watchdog(WATCHDOG_LIMIT, self._demoted)
        self.started = time.monotonic()
        self.went: float | None = None  # when the roles first started (every group ready)
        self.stop_since = 0.0

    # ---- the run ---------------------------------------------------------------------------
    def run(self) -> RunReport:
        remove_stale_segments()  # of earlier runs whose supervisor was killed
        remove_stale_cgroups()
        try:
            self._start(list(self.system.groups))
            next_status = time.monotonic()
            while self._live():
                # The timeout is the roles' time: it counts from "go", not from the processes'
                # start-up (spawning and importing can take seconds).
                deadline = None if self.timeout is None or self.went is None else self.went + self.timeout
                now = time.monotonic()
                if deadline is not None and now >= deadline and not self.stopping:
                    self._stop_all("the timeout passed")
                self._serve(_TICK)
                self._enforce_grace()
                self._check_start_timeouts()
                if self.on_status is not None and time.monotonic() >= next_status:
                    self.on_status(self._statuses())
                    next_status = time.monotonic() + _STATUS_EVERY
        except KeyboardInterrupt:
            self._stop_all("interrupted")
            while self._live():
                self._serve(_TICK)
                self._enforce_grace()
            raise
        finally:
            self.watchdog.stop()
            self._cleanup()
        report = self._report()
        if self.on_status is not None:
            self.on_status(self._statuses())
        return report

    def _live(self) -> bool:
        return any(inc.state != "ended" for inc in self.current.values())

    # ---- starting --------------------------------------------------------------------------
    def _start(self, names: list[str]) -> None:
        """Start ``names`` as one batch: pipes among them, dead channels to the others."""
        batch = set(names)
        pipes: dict[str, dict[tuple[str, str], Connection]] = {name: {} for name in names}
        for sender, receiver in self.channels:
            gs, gr = self.group_of[sender], self.group_of[receiver]
            if gs != gr and gs in batch and gr in batch:
                reader, writer = self.context.Pipe(duplex=False)
                pipes[gs][(sender, receiver)] = writer
                pipes[gr][(sender, receiver)] = reader
        for name in names:
            group = self.system.groups[name]
            number = self.current[name].number + 1 if name in self.current else 0
            inc = _Incarnation(group, number)
            dead = {role: f"group {self.group_of[role]} did not start again with group {name}"
                    for role in self.gt.roles if self.group_of[role] not in batch}
            spec = GroupSpec(
                run_id=self.run_id, name=name, incarnation=number, protocol=self.gt.name,
                roles={role: reference_of(fn) for role, fn in group.roles.items()},
                machines={role: self.machines[role] for role in group.roles},
                channels=self.channels, dead=dead, monitors=self.system.monitors,
                priority=group.priority, cpus=group.cpus, memory=group.memory,
                sys_path=tuple(p for p in _sys_path() if p))
            parent_end, child_end = self.context.Pipe()
            process = self.context.Process(target=group_main, args=(spec, child_end, pipes[name]),
                                           name=f"anodize:{name}", daemon=True)
            process.start()
            child_end.close()
            inc.process, inc.control, inc.pid = process, parent_end, process.pid
            self.current[name] = inc
        for ends in pipes.values():
            for conn in ends.values():
                conn.close()  # only the groups hold them now: a dead group means end-of-file

    def _on_ready(self, inc: _Incarnation, data: dict[str, Any]) -> None:
        inc.state = "ready"
        inc.scheduling = str(data.get("scheduling", ""))
        inc.baseline = int(data.get("baseline", 0))
        inc.memory_note = str(data.get("memory_note", ""))
        if inc.group.memory is not None:
            self._add_cgroup(inc)
        if inc.scheduling.startswith("SCHED_FIFO") and inc.pid:
            self.watchdog.watch(inc.group.name, inc.pid)
        self._maybe_go()

    def _maybe_go(self) -> None:
        """Once no group of the batch is still starting, let the ready ones go together."""
        if any(inc.state == "starting" for inc in self.current.values()):
            return
        for inc in self.current.values():
            if inc.state == "ready":
                inc.state = "running"
                self._tell(inc, "go")
                if self.went is None:
                    self.went = time.monotonic()

    def _check_start_timeouts(self) -> None:
        for inc in self.current.values():
            if inc.state == "starting" and time.monotonic() - inc.started_at > _START_TIMEOUT:
                self._group_failed(inc, RoleError(
                    "StartTimeout", f"group {inc.group.name}'s process did not get ready within "
                    f"{_START_TIMEOUT:g} s (importing its roles?)"))
                self._kill(inc, "failed")

    def _add_cgroup(self, inc: _Incarnation) -> None:
        cgroup, how = make_cgroup(f"anodize-{self.run_id}-{inc.group.name}-{inc.number}")
        if cgroup is None:
            inc.memory_note += f"; no cgroup backstop ({how})"
            return
        try:
            limit = (rss(inc.pid or 0) or 0) + (inc.group.memory or 0) + CGROUP_SLACK
            cgroup.set_limit(limit)
            cgroup.add(inc.pid or 0)
        except OSError as error:
            cgroup.remove()
            inc.memory_note += f"; no cgroup backstop ({how}: {error.strerror})"
            return
        inc.cgroup = cgroup
        inc.memory_note += f"; {how} backstop at {limit / 2**20:.0f} MiB resident"

    # ---- listening -------------------------------------------------------------------------
    def _serve(self, timeout: float) -> None:
        by_object: dict[Any, _Incarnation] = {}
        for inc in self.current.values():
            if inc.state == "ended":
                continue
            if inc.control is not None:
                by_object[inc.control] = inc
            by_object[inc.process.sentinel] = inc
        if not by_object:
            return
        for ready in wait(list(by_object), timeout):
            inc = by_object[ready]
            if inc.state == "ended":
                continue
            if ready is inc.control:
                self._read(inc)
            else:
                self._drain(inc)
                self._exited(inc)

    def _read(self, inc: _Incarnation) -> None:
        assert inc.control is not None
        try:
            kind, data = control_recv(inc.control)
        except (EOFError, OSError):
            inc.control = None  # the process is ending; its sentinel tells the rest
            return
        except DecodeError as error:
            self._group_failed(inc, RoleError("ControlError", f"garbled control message: {error}"))
            self._kill(inc, "failed")
            return
        try:
            self._dispatch(inc, kind, data)
        except (KeyError, TypeError, ValueError, AttributeError, IndexError) as error:
            # A group that garbles its reports is not trusted to run on.
            self._group_failed(inc, RoleError("ControlError", f"malformed {kind!r} report: {error}"))
            self._kill(inc, "failed")

    def _dispatch(self, inc: _Incarnation, kind: str, data: Any) -> None:
        if kind == "ready":
            self._on_ready(inc, data)
        elif kind in ("beat", "bye"):
            self._counts(inc, data)
        elif kind == "role":
            self._counts(inc, data)
            self._on_role(inc, data)
        elif kind == "memory":
            self._counts(inc, data)
            self._group_failed(inc, error_from_data(data["error"]))
        elif kind == "crash":
            self._group_failed(inc, error_from_data(data))
        else:
            raise ValueError(f"unknown report kind {kind!r}")

    def _drain(self, inc: _Incarnation) -> None:
        """Read what a process said before it exited."""
        while inc.control is not None and inc.control.poll(0):
            self._read(inc)

    def _counts(self, inc: _Incarnation, data: dict[str, Any]) -> None:
        if "sent" not in data:
            return
        history = self.history[inc.group.name]
        history.memory = int(data.get("memory", 0))
        history.peak = max(history.peak, int(data.get("peak", 0)))
        for channel, n in dict(data.get("sent", {})).items():
            history.sent[channel] = history.sent_before.get(channel, 0) + int(n)
        history.samples.append((time.monotonic(), sum(history.sent.values())))

    def _on_role(self, inc: _Incarnation, data: dict[str, Any]) -> None:
        role = str(data["role"])
        error = error_from_data(data["error"]) if data.get("error") else None
        status: Status = data["status"]
        inc.reports[role] = RoleReport(role, inc.group.name, status, error, inc.scheduling)
        if status == "failed":
            self._broadcast_failure(inc.group.name, {role: describe_error(error)})
            self._apply_policy(inc, f"role {role}: {describe_error(error)}")

    def _exited(self, inc: _Incarnation) -> None:
        inc.process.join(1.0)
        code = inc.process.exitcode
        inc.state = "ended"
        self.watchdog.forget(inc.group.name)
        missing = [r for r in inc.group.roles if r not in inc.reports]
        if missing and not inc.killed_on_purpose:
            error = inc.error or self._death_cause(inc, code)
            if inc.error is None:
                self._group_failed(inc, error)
        if inc.cgroup is not None:
            peak = inc.cgroup.peak()
            inc.cgroup.remove()
            if peak:
                inc.memory_note += f" (cgroup peak {peak / 2**20:.1f} MiB resident)"
        for role in missing:
            status: Status = "stopped" if inc.killed_on_purpose == "stop" and inc.error is None else "failed"
            inc.reports[role] = RoleReport(role, inc.group.name, status,
                                           None if status == "stopped" else inc.error, inc.scheduling)
        self._close(inc)
        if inc.killed_on_purpose == "restart":
            self._restart_when_ready()
        self._maybe_go()

    @staticmethod
    def _close(inc: _Incarnation) -> None:
        if inc.control is not None:
            inc.control.close()
            inc.control = None
        if inc.process is not None and not inc.process.is_alive():
            inc.process.close()
            inc.process = None

    def _death_cause(self, inc: _Incarnation, code: int | None) -> BaseException:
        history = self.history[inc.group.name]
        if inc.cgroup is not None and inc.cgroup.oom_killed():
            peak = max(history.peak, (inc.cgroup.peak() or 0) - inc.baseline)
            return MemoryBoundError(inc.group.name, inc.group.memory or 0, peak)
        if code == EXIT_MEMORY:
            return MemoryBoundError(inc.group.name, inc.group.memory or 0, history.peak)
        if code is not None and code < 0:
            try:
                name = signal.Signals(-code).name
            except ValueError:
                name = f"signal {-code}"
            return RoleError("ProcessDied", f"group {inc.group.name}'s process was killed by {name}")
        return RoleError("ProcessDied", f"group {inc.group.name}'s process exited with status {code} "
                                        "before its roles reported (its stderr says why; a script that "
                                        "runs a process system needs if __name__ == '__main__':)")

    # ---- failures --------------------------------------------------------------------------
    def _group_failed(self, inc: _Incarnation, error: BaseException) -> None:
        """The whole group failed (memory bound, crash, death): every unreported role with it."""
        if inc.error is not None:
            return
        inc.error = error
        missing = [r for r in inc.group.roles if r not in inc.reports]
        for role in missing:
            inc.reports[role] = RoleReport(role, inc.group.name, "failed", error, inc.scheduling)
        self._broadcast_failure(inc.group.name, dict.fromkeys(missing, describe_error(error)))
        self._apply_policy(inc, describe_error(error), whole_group=True)

    def _broadcast_failure(self, group: str, causes: dict[str, str]) -> None:
        for other in self.current.values():
            if other.group.name != group and other.state != "ended":
                for role, cause in causes.items():
                    self._tell(other, "failed", {"role": role, "cause": cause})

    def _apply_policy(self, inc: _Incarnation, what: str, whole_group: bool = False) -> None:
        history = self.history[inc.group.name]
        history.failures.append(f"{time.monotonic() - self.started:.2f} s: {what}")
        policy = inc.group.on_failure
        if self.stopping:
            return
        if policy == "stop-system":
            self._stop_all(f"group {inc.group.name} failed and its policy is stop-system")
        elif policy == "restart" and history.restarts < inc.group.max_restarts:
            for name in self._restart_set(inc.group.name):
                other = self.current[name]
                if other.state != "ended":
                    self._kill(other, "restart")
                else:
                    other.killed_on_purpose = "restart"
            self._restart_when_ready()
        elif whole_group and inc.state != "ended":
            self._kill(inc, "failed")  # stopped as a whole: all its threads, all its memory

    def _restart_set(self, name: str) -> list[str]:
        """``name`` and the groups connected to it through channels that also restart."""
        groups = self.system.groups
        found, todo = {name}, [name]
        while todo:
            current = todo.pop()
            for sender, receiver in self.channels:
                for a, b in ((sender, receiver), (receiver, sender)):
                    ga, gb = self.group_of[a], self.group_of[b]
                    if ga == current and gb not in found and groups[gb].on_failure == "restart" \
                            and self.history[gb].restarts < groups[gb].max_restarts:
                        found.add(gb)
                        todo.append(gb)
        return sorted(found)

    def _restart_when_ready(self) -> None:
        """Start the batch marked for restart once all of its old processes are gone."""
        marked = [n for n, inc in self.current.items() if inc.killed_on_purpose == "restart"]
        if not marked or any(self.current[n].state != "ended" for n in marked):
            return
        for name in marked:
            history = self.history[name]
            history.restarts += 1
            history.sent_before = dict(history.sent)
        self._start(marked)

    def _kill(self, inc: _Incarnation, why: str) -> None:
        inc.killed_on_purpose = inc.killed_on_purpose or why
        if inc.process is not None and inc.process.is_alive():
            inc.process.kill()

    def _stop_all(self, why: str) -> None:
        self.stopping = True
        self.stop_since = time.monotonic()
        self.notes.append(f"stopping every group: {why}")
        for inc in self.current.values():
            if inc.state != "ended":
                self._tell(inc, "stop")

    def _enforce_grace(self) -> None:
        if self.stopping and time.monotonic() - self.stop_since > self.grace:
            for inc in self.current.values():
                if inc.state != "ended":
                    self._kill(inc, "stop")

    def _tell(self, inc: _Incarnation, kind: str, data: object = None) -> None:
        if inc.control is None or inc.deaf:
            return
        try:
            control_send(inc.control, kind, data)
        except OSError:  # it is exiting; what it said before is still there to read
            inc.deaf = True

    def _demoted(self, group: str, description: str) -> None:
        self.history[group].notes.append(description)

    # ---- reporting -------------------------------------------------------------------------
    def _statuses(self) -> dict[str, GroupStatus]:
        statuses = {}
        for name, inc in self.current.items():
            history = self.history[name]
            state = inc.state
            if state == "ended":
                state = self._group_status(inc)
            elif state == "ready":
                state = "starting"
            rate = _last_rate(history.samples)
            statuses[name] = GroupStatus(name, state, inc.pid, history.memory,
                                         sum(history.sent.values()), rate, history.restarts,
                                         "; ".join(history.notes))
        return statuses

    @staticmethod
    def _group_status(inc: _Incarnation) -> Status:
        statuses = {r.status for r in inc.reports.values()}
        return "failed" if "failed" in statuses or inc.error else "stopped" if "stopped" in statuses else "done"

    def _report(self) -> RunReport:
        duration = time.monotonic() - self.started
        roles: dict[str, RoleReport] = {}
        groups: dict[str, GroupReport] = {}
        for name, inc in self.current.items():
            history = self.history[name]
            roles.update(inc.reports)
            rates = _window_rates(history.samples)
            note = "; ".join(filter(None, [inc.memory_note, *history.notes]))
            groups[name] = GroupReport(
                name, self._group_status(inc), inc.scheduling,
                history.peak if history.samples else None, note, inc.group.memory, inc.error,
                history.restarts, tuple(history.failures), sum(history.sent.values()),
                statistics.median(rates) if rates else None, min(rates) if rates else None, inc.pid)
        for role in self.gt.roles:
            roles.setdefault(role, RoleReport(role, self.group_of[role], "stopped"))
        messages = {f"{a}->{b}": 0 for a, b in self.channels}
        for history in self.history.values():
            for channel, n in history.sent.items():
                messages[channel] = n
        notes = [f"real-time guard: kernel RT throttling {rt_throttling()}; watchdog demotes a "
                 f"SCHED_FIFO group that keeps a CPU busy for {WATCHDOG_LIMIT:g} s", *self.notes]
        return RunReport(self.gt.name, {r: roles[r] for r in self.gt.roles}, groups, messages,
                         duration, "process", tuple(notes))

    def _cleanup(self) -> None:
        for inc in self.current.values():
            if inc.process is not None and inc.process.is_alive():
                inc.process.kill()
                inc.process.join(5.0)
            if inc.cgroup is not None:
                inc.cgroup.remove()
            self._close(inc)
        remove_run_segments(self.run_id)


def _sys_path() -> list[str]:
    return [os.path.abspath(p) for p in sys.path]


def _window_rates(samples: list[tuple[float, int]], window: float = 1.0) -> list[float]:
    """Messages per second over consecutive windows of at least ``window`` seconds."""
    rates = []
    if not samples:
        return rates
    start_t, start_n = samples[0]
    for t, n in samples[1:]:
        if t - start_t >= window:
            rates.append((n - start_n) / (t - start_t))
            start_t, start_n = t, n
    return rates


def _last_rate(samples: list[tuple[float, int]]) -> float | None:
    recent = [s for s in samples if samples[-1][0] - s[0] <= 1.0] if samples else []
    if len(recent) < 2 or recent[-1][0] <= recent[0][0]:
        return None
    return (recent[-1][1] - recent[0][1]) / (recent[-1][0] - recent[0][0])

