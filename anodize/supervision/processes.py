"""The runner of ``transport="process"``: one OS process per group.

It spawns one process per group (:mod:`.groupproc`), wires a pipe for every
channel between roles of different groups, and then only listens: to each
group's control connection (typed messages, :mod:`.control`) and to each
process's exit, which it turns into events for the supervision core. It never
carries protocol messages. It also owns what only processes have: the cgroup
backstop of a memory bound, the real-time watchdog and the start-up deadline.
"""

from __future__ import annotations

import multiprocessing
import os
import secrets
import signal
import sys
import time
from collections.abc import Sequence
from multiprocessing.connection import Connection, wait
from typing import Any

from sessiontypes import StateMachine

from ..errors import MemoryBoundError, RoleError, error_from_data
from ..isolation.memory import CGROUP_SLACK, Cgroup, make_cgroup, remove_stale_cgroups, rss
from ..isolation.watchdog import Watchdog, rt_throttling
from ..transport.codec import DecodeError
from ..transport.shm import remove_run_segments, remove_stale_segments
from . import control
from .group import Group, reference_of
from .groupproc import EXIT_MEMORY, GroupSpec, group_main
from .report import RoleReport, RoleStatus
from .supervisor import Counts, Event, GroupExited, GroupFailed, Note, Ready, RoleEnded

__all__ = ["ProcessRunner", "WATCHDOG_LIMIT"]

WATCHDOG_LIMIT = 0.5  # seconds a FIFO group may keep a CPU busy before it is demoted (< RT throttling's 0.95 s)
_START_TIMEOUT = 60.0  # seconds for a group's process to import its roles and report ready


class _Incarnation:
    """One group's current process and what the runner knows of it."""

    def __init__(self, group: Group, number: int, process: Any, control_end: Connection) -> None:
        self.group = group
        self.number = number
        self.process: Any = process
        self.control: Connection | None = control_end
        self.pid: int | None = process.pid
        self.baseline = 0
        self.peak = 0
        self.cgroup: Cgroup | None = None
        self.started_at = time.monotonic()
        self.ready = False
        self.ended = False
        self.failed = False  # a GroupFailed was sent for it
        self.deaf = False  # its end of the control connection is closed for our messages


class ProcessRunner:
    """Starts groups as processes; see the module docstring."""

    transport = "process"

    def __init__(self, protocol: str, machines: dict[str, StateMachine], channels: Sequence[tuple[str, str]],
                 groups: dict[str, Group], monitors: bool) -> None:
        self.protocol = protocol
        self.machines = machines
        self.channels = tuple(channels)
        self.groups = groups
        self.monitors = monitors
        self.group_of = {role: g.name for g in groups.values() for role in g.roles}
        self.run_id = f"{os.getpid()}-{secrets.token_hex(3)}"
        self.context = multiprocessing.get_context("spawn")  # a fresh interpreter: nothing shared
        self.current: dict[str, _Incarnation] = {}
        self.pending: list[Event] = []
        self.watchdog = Watchdog(WATCHDOG_LIMIT, self._demoted)
        remove_stale_segments()  # of earlier runs whose supervisor was killed
        remove_stale_cgroups()

    # ---- starting --------------------------------------------------------------------------
    def start(self, groups: Sequence[str], incarnation: int) -> None:
        """Start ``groups`` as one batch: pipes among them, dead channels to the others."""
        batch = set(groups)
        pipes: dict[str, dict[tuple[str, str], Connection]] = {name: {} for name in groups}
        for sender, receiver in self.channels:
            gs, gr = self.group_of[sender], self.group_of[receiver]
            if gs != gr and gs in batch and gr in batch:
                reader, writer = self.context.Pipe(duplex=False)
                pipes[gs][(sender, receiver)] = writer
                pipes[gr][(sender, receiver)] = reader
        for name in groups:
            group = self.groups[name]
            dead = {role: f"group {self.group_of[role]} did not start again with group {name}"
                    for role in self.machines if self.group_of[role] not in batch}
            spec = GroupSpec(
                run_id=self.run_id, name=name, incarnation=incarnation, protocol=self.protocol,
                roles={role: reference_of(fn) for role, fn in group.roles.items()},
                machines={role: self.machines[role] for role in group.roles},
                channels=self.channels, dead=dead, monitors=self.monitors,
                priority=group.priority, cpus=group.cpus, memory=group.memory,
                sys_path=tuple(p for p in _sys_path() if p))
            parent_end, child_end = self.context.Pipe()
            process = self.context.Process(target=group_main, args=(spec, child_end, pipes[name]),
                                           name=f"anodize:{name}", daemon=True)
            process.start()
            child_end.close()
            self.current[name] = _Incarnation(group, incarnation, process, parent_end)
        for ends in pipes.values():
            for conn in ends.values():
                conn.close()  # only the groups hold them now: a dead group means end-of-file

    def _on_ready(self, inc: _Incarnation, ready: control.Ready) -> None:
        inc.ready = True
        inc.baseline = ready.baseline
        note = ready.memory_note
        if inc.group.memory is not None:
            note += self._add_cgroup(inc)
        if ready.scheduling.startswith("SCHED_FIFO") and inc.pid:
            self.watchdog.watch(inc.group.name, inc.pid)
        self.pending.append(Ready(group=inc.group.name, incarnation=inc.number, scheduling=ready.scheduling,
                                  memory_note=note, pid=inc.pid))

    def _add_cgroup(self, inc: _Incarnation) -> str:
        cgroup, how = make_cgroup(f"anodize-{self.run_id}-{inc.group.name}-{inc.number}")
        if cgroup is None:
            return f"; no cgroup backstop ({how})"
        try:
            limit = (rss(inc.pid or 0) or 0) + (inc.group.memory or 0) + CGROUP_SLACK
            cgroup.set_limit(limit)
            cgroup.add(inc.pid or 0)
        except OSError as error:
            cgroup.remove()
            return f"; no cgroup backstop ({how}: {error.strerror})"
        inc.cgroup = cgroup
        return f"; {how} backstop at {limit / 2**20:.0f} MiB resident"

    def go(self, group: str) -> None:
        self._tell(self.current[group], control.Go())

    # ---- listening -------------------------------------------------------------------------
    def events(self, timeout: float) -> list[Event]:
        by_object: dict[Any, _Incarnation] = {}
        for inc in self.current.values():
            if inc.ended:
                continue
            if inc.control is not None:
                by_object[inc.control] = inc
            by_object[inc.process.sentinel] = inc
        if by_object and not self.pending:
            for ready in wait(list(by_object), timeout):
                inc = by_object[ready]
                if inc.ended:
                    continue
                if ready is inc.control:
                    self._read(inc)
                else:
                    self._drain(inc)
                    self._exited(inc)
        elif not by_object and not self.pending:
            time.sleep(min(timeout, 0.01))
        self._check_start_timeouts()
        found, self.pending = self.pending, []
        return found

    def _read(self, inc: _Incarnation) -> None:
        assert inc.control is not None
        try:
            message = control.recv_control(inc.control)
        except (EOFError, OSError):
            inc.control = None  # the process is ending; its sentinel tells the rest
            return
        except DecodeError as error:  # a group that garbles its reports is not trusted to run on
            self._fail(inc, RoleError("ControlError", f"garbled control message: {error}"))
            return
        name, number = inc.group.name, inc.number
        match message:
            case control.Ready():
                self._on_ready(inc, message)
            case control.Beat():
                inc.peak = max(inc.peak, message.peak)
                self.pending.append(Counts(group=name, incarnation=number, at=message.at, sent=message.sent,
                                           received=message.received, memory=message.memory, peak=message.peak))
            case control.RoleEnded():
                self.pending.append(RoleEnded(group=name, incarnation=number, report=_role_report(name, message)))
            case control.MemoryExceeded():
                self._fail(inc, error_from_data(message.error))
            case control.Crash():
                self._fail(inc, error_from_data(message.error))
            case _:
                self._fail(inc, RoleError("ControlError", f"a group may not send {type(message).__name__}"))

    def _fail(self, inc: _Incarnation, error: BaseException) -> None:
        if not inc.failed:
            inc.failed = True
            self.pending.append(GroupFailed(group=inc.group.name, incarnation=inc.number, error=error))

    def _drain(self, inc: _Incarnation) -> None:
        """Read what a process said before it exited."""
        while inc.control is not None and inc.control.poll(0):
            self._read(inc)

    def _exited(self, inc: _Incarnation) -> None:
        inc.process.join(1.0)
        code = inc.process.exitcode
        inc.ended = True
        self.watchdog.forget(inc.group.name)
        if code != 0:
            self._fail(inc, self._death_cause(inc, code))
        note = ""
        if inc.cgroup is not None:
            peak = inc.cgroup.peak()
            inc.cgroup.remove()
            if peak:
                note = f"cgroup peak {peak / 2**20:.1f} MiB resident"
        if note:
            self.pending.append(Note(group=inc.group.name, text=note))
        self._close(inc)
        self.pending.append(GroupExited(group=inc.group.name, incarnation=inc.number,
                                        unreported=f"its process ended (exit status {code})"))

    def _death_cause(self, inc: _Incarnation, code: int | None) -> BaseException:
        name = inc.group.name
        if inc.cgroup is not None and inc.cgroup.oom_killed():
            peak = max(inc.peak, (inc.cgroup.peak() or 0) - inc.baseline)
            return MemoryBoundError(name, inc.group.memory or 0, peak)
        if code == EXIT_MEMORY:
            return MemoryBoundError(name, inc.group.memory or 0, inc.peak)
        if code is not None and code < 0:
            try:
                signame = signal.Signals(-code).name
            except ValueError:
                signame = f"signal {-code}"
            return RoleError("ProcessDied", f"group {name}'s process was killed by {signame}")
        return RoleError("ProcessDied", f"group {name}'s process exited with status {code} before its roles "
                                        "reported (its stderr says why; a script that runs a process system "
                                        "needs if __name__ == '__main__':)")

    def _check_start_timeouts(self) -> None:
        for inc in self.current.values():
            if not inc.ready and not inc.ended and time.monotonic() - inc.started_at > _START_TIMEOUT:
                self._fail(inc, RoleError("StartTimeout", f"group {inc.group.name}'s process did not get ready "
                                                          f"within {_START_TIMEOUT:g} s (importing its roles?)"))
                self.kill(inc.group.name)

    @staticmethod
    def _close(inc: _Incarnation) -> None:
        if inc.control is not None:
            inc.control.close()
            inc.control = None
        if inc.process is not None and not inc.process.is_alive():
            inc.process.close()
            inc.process = None

    # ---- the supervisor's word -------------------------------------------------------------
    def tell_failed(self, group: str, role: str, cause: str) -> None:
        self._tell(self.current[group], control.PeerFailed(role=role, cause=cause))

    def stop(self, group: str) -> None:
        self._tell(self.current[group], control.Stop())

    def kill(self, group: str) -> None:
        inc = self.current[group]
        if inc.process is not None and inc.process.is_alive():
            inc.process.kill()

    def _tell(self, inc: _Incarnation, message: control.SupervisorMessage) -> None:
        if inc.control is None or inc.deaf or inc.ended:
            return
        try:
            control.send_control(inc.control, message)
        except OSError:  # it is exiting; what it said before is still there to read
            inc.deaf = True

    def _demoted(self, group: str, description: str) -> None:
        self.pending.append(Note(group=group, text=description))

    def notes(self) -> list[str]:
        return [(f"real-time guard: kernel RT throttling {rt_throttling()}; watchdog demotes a SCHED_FIFO "
                 f"group that keeps a CPU busy for {WATCHDOG_LIMIT:g} s")]

    def close(self) -> None:
        self.watchdog.stop()
        for inc in self.current.values():
            if inc.process is not None and inc.process.is_alive():
                inc.process.kill()
                inc.process.join(5.0)
            if inc.cgroup is not None:
                inc.cgroup.remove()
            self._close(inc)
        remove_run_segments(self.run_id)


def _role_report(group: str, message: control.RoleEnded) -> RoleReport:
    try:
        status = RoleStatus(message.status)
    except ValueError:
        status = RoleStatus.FAILED
    error = error_from_data(message.error) if message.error else None
    if status is RoleStatus.FAILED and error is None:
        error = RoleError("ControlError", f"role reported failed with status {message.status!r} and no error")
    return RoleReport(name=message.role, group=group, status=status, error=error, where=message.where,
                      traceback=message.traceback, detail=message.detail)


def _sys_path() -> list[str]:
    return [os.path.abspath(p) for p in sys.path]
