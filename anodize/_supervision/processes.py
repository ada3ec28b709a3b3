"""The runner of ``Processes``: one OS process per group.

It spawns one process per group (:mod:`.groupproc`), wires a pipe for every
channel between roles of different groups, and then only listens: to each
group's control connection (typed messages, :mod:`.control`) and to each
process's exit, which it turns into events for the supervision core. It never
carries protocol messages. It also owns what only processes have: the cgroup
backstop of a memory bound, the real-time watchdog and the start-up deadline.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import secrets
import signal
import sys
import time
from collections.abc import Sequence
from multiprocessing.connection import Connection, wait
from typing import TYPE_CHECKING, Any

from .._isolation.inherit import Boosts, inheritance_table
from .._isolation.memory import (
    CGROUP_SLACK,
    Cgroup,
    make_cgroup,
    open_tmpfs_bytes,
    peak_rss,
    remove_stale_cgroups,
    rss,
    tmpfs_devices,
)
from .._isolation.tree import kill_remembered, kill_tree, snapshot
from .._isolation.watchdog import Watchdog, rt_throttling
from .._transport.codec import DecodeError
from .._transport.process import LinkEnd, channel_ends
from .._transport.shm import remove_run_segments, remove_stale_segments, segment_dir
from .._transport.spin import describe_spin, spin_refusal
from ..errors import MemoryBoundError, RoleError, error_from_data
from . import control
from .events import Counts, Event, GroupExited, GroupFailed, Logged, Note, Ready, RoleEnded
from .group import Group, reference_of
from .groupproc import EXIT_MEMORY, GroupSpec, group_main
from .liveness import Frozen, HoldingGil
from .logcarry import from_message
from .plan import RunPlan
from .report import RoleReport, RoleStatus
from .runner import Scope
from .watching import LivenessWatch

if TYPE_CHECKING:
    from .._transport.links import NetworkSettings

__all__ = ["ProcessRunner", "WATCHDOG_LIMIT"]

WATCHDOG_LIMIT = 0.5  # seconds a FIFO group may keep a CPU busy before it is demoted (< RT throttling's 0.95 s)
_MEMORY_EVERY = 0.1  # seconds between two measurements of every group's memory
_START_TIMEOUT = 60.0  # seconds for a group's process to import its roles and report ready
_CLOSE_WAIT = 5.0  # seconds, in all, for killed group processes to be reaped at the end of a run


class _Incarnation:
    """One group's current process and what the runner knows of it."""

    def __init__(self, group: Group, number: int, process: Any, control_end: Connection) -> None:
        self.group = group
        self.number = number
        self.process: Any = process
        self.control: Connection | None = control_end
        self.reader: control.FrameReader | None = control.FrameReader(control_end.fileno())
        self.last_heard = time.monotonic()
        self.pid: int | None = process.pid
        # Readable when the process ends, whoever else holds its pipes (multiprocessing's sentinel
        # is a pipe its children inherit: a forked child kept it open, and the death unseen).
        self.pidfd: int | None = _pidfd(process.pid)
        self.tree: dict[int, int] = {}  # its descendants at the last look (pid -> start time)
        self.baseline = 0
        self.baseline_resident = 0
        self.resident = 0
        self.peak = 0
        self.cgroup: Cgroup | None = None
        self.files_baseline: int | None = None  # without a cgroup: the open tmpfs files at "ready"
        self.started_at = time.monotonic()
        self.ready = False
        self.ended = False
        self.failed = False  # a GroupFailed was sent for it
        self.deaf = False  # its end of the control connection is closed for our messages


class ProcessRunner:
    """Starts groups as processes; see the module docstring."""

    transport = "process"

    def __init__(self, plan: RunPlan, liveness: float = 2.0) -> None:
        self.plan = plan
        self.protocol = plan.protocol
        self.liveness = liveness
        self.capacities = dict(plan.capacities or {})
        self.machines = dict(plan.machines)
        self.channels = tuple(plan.channels)
        self.groups = dict(plan.groups)
        self.monitors = plan.monitors
        self.group_of = {role: g.name for g in self.groups.values() for role in g.roles}
        self.scope = Scope(self.groups, tuple(r for r in plan.global_type.roles if r in self.group_of), self.channels)
        self.run_id = f"{os.getpid()}-{secrets.token_hex(3)}"
        self.context = multiprocessing.get_context("spawn")  # a fresh interpreter: nothing shared
        self.current: dict[str, _Incarnation] = {}
        self.pending: list[Event] = []
        self.next_memory_check = 0.0
        self.tmpfs = tmpfs_devices()
        self.watchdog = Watchdog(WATCHDOG_LIMIT, self._demoted)
        self.watch = LivenessWatch(liveness)  # the liveness rule's samples (see .liveness)
        self.start_timeout = _START_TIMEOUT
        remove_stale_segments()  # of earlier runs whose supervisor was killed (the inheritance table too)
        remove_stale_cgroups()
        # Priority inheritance: one table every group process of this host maps (a DdsRunner passes
        # only this host's groups: roles elsewhere are not in it, and nobody lends to them).
        self.inheritance_note = ""
        try:
            self.inheritance = inheritance_table(self.groups.values(),
                                                 os.path.join(segment_dir(), f"anodize-{self.run_id}-inherit"))
        except OSError as error:  # no shared memory to put the table in: inheritance is off, and says so
            self.inheritance = None
            self.inheritance_note = (f"priority inheritance off: its table could not be made in {segment_dir()} "
                                     f"({error})")
        self.boosts: dict[tuple[str, str], Boosts] = {}
        self.inactive: list[str] = []

    # ---- starting --------------------------------------------------------------------------
    def start(self, groups: Sequence[str], incarnation: int) -> None:
        """Start ``groups`` as one batch: pipes among them, dead channels to the others."""
        batch = set(groups)
        pipes: dict[str, dict[tuple[str, str], LinkEnd]] = {name: {} for name in groups}
        for sender, receiver in self.channels:
            gs, gr = self.group_of[sender], self.group_of[receiver]
            if gs != gr and gs in batch and gr in batch:
                reader, writer = channel_ends(self.context)  # a pipe and a shared-memory ring
                pipes[gs][(sender, receiver)] = writer
                pipes[gr][(sender, receiver)] = reader
        for name in groups:
            dead = {role: f"group {self.group_of[role]} did not start again with group {name}"
                    for role in self.machines if self.group_of[role] not in batch}
            self._launch(name, incarnation, dead, pipes[name])
        for ends in pipes.values():
            for conn in ends.values():
                conn.close()  # only the groups hold them now: a dead group means end-of-file

    def _launch(self, name: str, incarnation: int, dead: dict[str, str],
                pipes: dict[tuple[str, str], LinkEnd], network: NetworkSettings | None = None) -> None:
        """Start group ``name``'s process: its spec, with ``dead`` (role -> why its channels are
        gone), its ends of the pipes to the rest of its batch, and its network transport's settings
        where channels between groups are DDS topics or Zenoh keys."""
        group = self.groups[name]
        spec = GroupSpec(
            run_id=self.run_id, name=name, incarnation=incarnation, protocol=self.protocol,
            roles={role: reference_of(fn) for role, fn in group.roles.items()},
            machines={role: self.machines[role] for role in group.roles},
            channels=self.channels, dead=dead, monitors=self.monitors,
            priority=group.priority, nice=group.nice, cpus=group.cpus, memory=group.memory,
            sys_path=tuple(p for p in _sys_path() if p), capacities=self.capacities,
            taps=self.plan.taps, network=network,
            inheritance=None if self.inheritance is None else (self.inheritance.seats, self.inheritance.path),
            params={role: dict(values) for role, values in (self.plan.params or {}).items() if role in group.roles},
            **self._spin(group, network is not None))
        parent_end, child_end = self.context.Pipe()
        process = self.context.Process(target=group_main, args=(spec, child_end, pipes),
                                       name=f"anodize:{name}", daemon=True)
        process.start()
        child_end.close()
        self.current[name] = _Incarnation(group, incarnation, process, parent_end)

    def _spin(self, group: Group, on_network: bool) -> dict[str, Any]:
        """GroupSpec's ``spin`` (nanoseconds, 0: off) and ``spin_note`` for ``group``: what it asked,
        or why it may not (a FIFO group sharing a CPU: anodize._transport.spin.spin_refusal)."""
        if not group.spin:
            return {}
        asked = describe_spin(group.spin)
        if on_network:
            return {"spin_note": f"spin {asked} not used: network links wait in their transport"}
        others = {g.name: g.cpus for g in self.groups.values() if g.name != group.name}
        refusal = spin_refusal(group.priority, group.cpus, others)
        if refusal is not None:
            return {"spin_note": f"spin {asked} refused: {refusal}"}
        return {"spin": group.spin, "spin_note": f"spin then park, up to {asked} (adaptive)"}

    def _on_ready(self, inc: _Incarnation, ready: control.Ready) -> None:
        inc.ready = True
        self.watch.forget(inc.group.name)
        inc.baseline = ready.baseline
        inc.baseline_resident = rss(inc.pid or 0) or 0
        note = ready.memory_note
        if inc.group.memory is not None:
            note += self._add_cgroup(inc)
            note += (f"; the bound covers resident memory above the {inc.baseline_resident / 2**20:.1f} MiB "
                     f"baseline (heap, mappings, shared-memory rings, its children), checked every "
                     f"{_MEMORY_EVERY:g} s by the supervisor")
            if inc.cgroup is None:
                inc.files_baseline = open_tmpfs_bytes([inc.pid or 0, *inc.tree], self.tmpfs)
                note += (" (with no cgroup, a burst faster than that can pass the bound before the group is "
                         "stopped; tmpfs files (/dev/shm) count only while its processes hold them open: "
                         "one it wrote and closed, or handed to a process outside the group, is not bounded)")
        if inc.pid:  # every group: priority inheritance can make any group's threads real time
            self.watchdog.watch(inc.group.name, inc.pid)
        self.pending.append(Ready(group=inc.group.name, incarnation=inc.number, scheduling=ready.scheduling,
                                  memory_note=note, pid=inc.pid))

    def _add_cgroup(self, inc: _Incarnation) -> str:
        cgroup, how = make_cgroup(f"anodize-{self.run_id}-{inc.group.name}-{inc.number}")
        if cgroup is None:
            return f"; no cgroup backstop ({how})"
        try:
            limit = inc.baseline_resident + (inc.group.memory or 0) + CGROUP_SLACK
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
            by_object[inc.process.sentinel if inc.pidfd is None else inc.pidfd] = inc
        self.watch.begin()
        started = time.monotonic()
        if by_object and not self.pending:
            woken = wait(list(by_object), timeout)
            self.watch.turn(started, started + timeout, time.monotonic())
            for ready in woken:
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
            self.watch.turn(started, started + min(timeout, 0.01), time.monotonic())
        else:
            self.watch.turn(started, None, time.monotonic())
        self._check_start_timeouts()
        self._check_liveness()
        self._account_memory()
        found, self.pending = self.pending, []
        return found

    def _read(self, inc: _Incarnation) -> None:
        """Read what the group's control connection holds (it is readable): never blocks on
        a partial message."""
        assert inc.control is not None and inc.reader is not None
        try:
            frames = inc.reader.read()
            messages = [control.decode_control(frame) for frame in frames]
        except OSError:
            inc.control = None  # the process is ending; its sentinel tells the rest
            return
        except DecodeError as error:  # a group that garbles its reports is not trusted to run on
            self._fail(inc, RoleError("ControlError", f"garbled control message: {error}"))
            self.kill(inc.group.name)
            return
        if inc.reader.eof:
            inc.control = None
        if frames:
            inc.last_heard = max(inc.last_heard, _sent_at(messages, time.monotonic()))
        for message in messages:
            self._on_message(inc, message)

    def _on_message(self, inc: _Incarnation, message: control.GroupMessage | control.SupervisorMessage) -> None:
        name, number = inc.group.name, inc.number
        match message:
            case control.Ready():
                self._on_ready(inc, message)
            case control.Beat():  # counts from the group; memory is measured here, from the kernel
                self.pending.append(Counts(group=name, incarnation=number, at=message.at, sent=message.sent,
                                           received=message.received, waiting=message.waiting,
                                           memory=inc.resident, peak=inc.peak, checked=message.checked,
                                           closest=message.closest, timeouts=message.timeouts))
            case control.RoleEnded():
                self.pending.append(RoleEnded(group=name, incarnation=number, report=_role_report(name, message)))
            case control.MemoryExceeded():  # the peak is measured here, as for the group's line
                if not inc.failed and inc.ready and inc.pid is not None:
                    self._measure(inc, time.monotonic())
                # Our samples (every 0.1 s) may miss a quick allocation on a busy machine, and the
                # process may be gone by now: the group measured its own growth when it met its bound.
                reported = error_from_data(message.error)
                if isinstance(reported, MemoryBoundError) and reported.peak > inc.peak:
                    inc.peak = reported.peak
                    self.pending.append(Counts(group=name, incarnation=number, at=time.monotonic(),
                                               memory=inc.resident, peak=inc.peak))
                self._fail(inc, MemoryBoundError(name, inc.group.memory or 0, inc.peak))
            case control.Crash():
                self._fail(inc, error_from_data(message.error))
            case control.Logs():
                try:
                    entries = from_message(message, name, tuple(inc.group.roles))
                except ValueError as error:  # as garbled as a bad frame
                    self._fail(inc, RoleError("ControlError", f"garbled control message: {error}"))
                    self.kill(inc.group.name)
                    return
                self.pending.append(Logged(entries=tuple(entries), dropped=dict(message.dropped)))
            case control.Notice():  # the group's own words: shown as what it says, not as a finding
                self.pending.append(Note(group=name, text=f"group {name} reports: {message.text[:2000]}"))
            case _:
                self._fail(inc, RoleError("ControlError", f"a group may not send {type(message).__name__}"))
                self.kill(inc.group.name)

    def _account_memory(self) -> None:
        """Measure what each group holds (resident memory of its process tree, from the kernel,
        so no call holding the group's GIL can hide it), keep the true peak, enforce the bound."""
        now = time.monotonic()
        if now < self.next_memory_check:
            return
        self.next_memory_check = now + _MEMORY_EVERY
        for inc in self.current.values():
            if inc.ended or inc.pid is None:
                continue
            tree = snapshot(inc.pid)  # what dies with it if it dies (it adopts what they orphan)
            if self._has_ended(inc):
                continue  # a dead process has no children left to read: the last look stands
            inc.tree = tree
            if not inc.ready or inc.failed:  # a failed group's peak is the one its error names
                continue
            self._measure(inc, now)
            bound = inc.group.memory
            if bound is not None and inc.resident > bound:
                self._fail(inc, MemoryBoundError(inc.group.name, bound, inc.peak))
                self.kill(inc.group.name)

    def _measure(self, inc: _Incarnation, now: float) -> None:
        """The group's memory now and its peak: the one source of both the group's line and any
        MemoryBoundError it gets."""
        assert inc.pid is not None
        tree = [inc.pid, *inc.tree]
        resident = sum(rss(pid) or 0 for pid in tree) - inc.baseline_resident
        if inc.files_baseline is not None:  # no cgroup: tmpfs pages it holds are no process's RSS
            resident += open_tmpfs_bytes(tree, self.tmpfs) - inc.files_baseline
        kernel_peak = (peak_rss(inc.pid) or 0) - inc.baseline_resident  # the root's high-water mark
        # Not the cgroup's peak: it counts the page cache of the files the group read (a camera
        # replaying a sequence from a cold cache showed a 508 MiB "peak" at 25 MiB resident).
        # It is the peak only when the kernel killed the group at its limit (_death_cause).
        inc.resident = max(0, resident)
        inc.peak = max(inc.peak, inc.resident, kernel_peak)
        self.pending.append(Counts(group=inc.group.name, incarnation=inc.number, at=now,
                                   memory=inc.resident, peak=inc.peak))

    def _check_liveness(self) -> None:
        """A group silent past the limit *in time it could run* is failed: stopped (SIGSTOP), a
        call holding the GIL, asleep, or half a control message and nothing more. A group the
        machine did not give the CPU is reported starved, not failed (the rule: .liveness)."""
        now = time.monotonic()
        watched = {name: (inc.pid, inc.last_heard) for name, inc in self.current.items()
                   if inc.ready and not inc.ended and not inc.failed and inc.pid is not None}
        self.watch.sample(watched, now)
        for inc in self.current.values():
            if inc.ended or inc.failed or not inc.ready or inc.pid is None:
                continue
            name = inc.group.name
            if self._has_ended(inc):  # dead, not silent: its exit status says what happened
                self._drain(inc)
                self._exited(inc)
                continue
            if now - inc.last_heard > self.liveness and inc.control is not None and inc.control.poll(0):
                self._read(inc)  # what it sent while this loop did not run is not silence
            verdict, notes = self.watch.check(name, inc.pid, inc.last_heard, now)
            self.pending.extend(Note(group=name, text=text) for text in notes)
            if not isinstance(verdict, Frozen | HoldingGil):
                continue
            partial = inc.reader.partial_since if inc.reader is not None else None
            if partial is not None:
                self._fail(inc, RoleError("ControlError", f"group {name} sent part of a control "
                                                          f"message and nothing more for {now - partial:.1f} s"))
            else:
                if isinstance(verdict, HoldingGil):
                    why = (f"its process ran ({verdict.cpu:.1f} s of CPU) but its heartbeat thread did not: "
                           "a call that holds the GIL")
                else:
                    why = f"frozen: {verdict.why}"
                self._fail(inc, RoleError("Unresponsive", f"group {name} sent no heartbeat for {verdict.silent:.1f} s "
                                                          f"(the limit is {self.liveness:g} s): {why}"))
            self.pending.extend(Note(group=name, text=text) for text in self.watch.forget(name))
            self.kill(name)

    def _fail(self, inc: _Incarnation, error: BaseException) -> None:
        if not inc.failed:
            inc.failed = True
            self.pending.append(GroupFailed(group=inc.group.name, incarnation=inc.number, error=error))

    def _drain(self, inc: _Incarnation) -> None:
        """Read what a process said before it exited."""
        while inc.control is not None and inc.control.poll(0):
            self._read(inc)

    @staticmethod
    def _has_ended(inc: _Incarnation) -> bool:
        """Whether the process has exited (without reaping it: :meth:`_exited` does)."""
        if inc.pidfd is None:
            return False  # its sentinel tells, in events()
        return bool(wait([inc.pidfd], 0))

    @staticmethod
    def _reap(inc: _Incarnation, timeout: float) -> None:
        """Wait up to ``timeout`` for the process to end, and reap it. Not ``Process.join``: that
        waits on the sentinel pipe, which a child of the group may hold open after its death."""
        if inc.process is None:
            return
        if inc.pidfd is None:
            inc.process.join(timeout)
        elif wait([inc.pidfd], timeout):
            _ = inc.process.exitcode  # waitpid, at once: the process has exited

    def _exited(self, inc: _Incarnation) -> None:
        self._reap(inc, 1.0)
        code = inc.process.exitcode
        inc.ended = True
        if inc.cgroup is not None:
            inc.cgroup.kill_all()
        kill_remembered(inc.tree)  # its orphans went to init: a group's children do not outlive it
        self.watchdog.forget(inc.group.name)
        self.pending.extend(Note(group=inc.group.name, text=text) for text in self.watch.forget(inc.group.name))
        if code != 0:
            self._fail(inc, self._death_cause(inc, code))
        note = ""
        if inc.cgroup is not None:
            peak = inc.cgroup.peak()
            inc.cgroup.remove()
            if peak:
                note = f"cgroup peak {peak / 2**20:.1f} MiB (resident and page cache)"
        if note:
            self.pending.append(Note(group=inc.group.name, text=note))
        self._close(inc)
        if self.inheritance is not None:  # a process that died waiting leaves no peer boosted
            self.inheritance.release(list(inc.group.roles))
        self.pending.append(GroupExited(group=inc.group.name, incarnation=inc.number,
                                        unreported=f"its process ended (exit status {code})"))

    def _death_cause(self, inc: _Incarnation, code: int | None) -> BaseException:
        name = inc.group.name
        if inc.cgroup is not None and inc.cgroup.oom_killed():
            inc.peak = max(inc.peak, (inc.cgroup.peak() or 0) - inc.baseline_resident)
            # The report's peak is the one the error names (the last sample may predate the kill).
            self.pending.append(Counts(group=name, incarnation=inc.number, at=time.monotonic(),
                                       memory=inc.resident, peak=inc.peak))
            return MemoryBoundError(name, inc.group.memory or 0, inc.peak)
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
            if not inc.ready and not inc.ended and time.monotonic() - inc.started_at > self.start_timeout:
                self._fail(inc, RoleError("StartTimeout", f"group {inc.group.name}'s process did not get ready "
                                                          f"within {self.start_timeout:g} s (importing its roles?)"))
                self.kill(inc.group.name)

    @staticmethod
    def _close(inc: _Incarnation) -> None:
        if inc.control is not None:
            inc.control.close()
            inc.control = None
        if inc.pidfd is not None:
            os.close(inc.pidfd)
            inc.pidfd = None
        if inc.process is not None and not inc.process.is_alive():
            inc.process.close()
            inc.process = None

    # ---- the supervisor's word -------------------------------------------------------------
    def tell_failed(self, group: str, role: str, cause: str) -> None:
        self._tell(self.current[group], control.PeerFailed(role=role, cause=cause))

    def stop(self, group: str) -> None:
        self._tell(self.current[group], control.Stop())

    def kill(self, group: str) -> None:
        """SIGKILL the group's whole process tree (its process adopts what its roles start)
        and, where it has one, every process in its cgroup."""
        inc = self.current[group]
        if inc.process is not None and inc.process.is_alive() and inc.pid is not None:
            kill_tree(inc.pid)  # it adopts what its roles start: the tree is the whole group
        if inc.cgroup is not None:
            inc.cgroup.kill_all()

    def _tell(self, inc: _Incarnation, message: control.SupervisorMessage) -> None:
        if inc.control is None or inc.deaf or inc.ended:
            return
        try:
            control.send_control(inc.control, message)
        except OSError:  # it is exiting; what it said before is still there to read
            inc.deaf = True

    def _demoted(self, group: str, description: str) -> None:
        if self.inheritance is not None:  # a demoted group is not boosted back up by a waiter
            self.inheritance.demote(list(self.groups[group].roles))
        self.pending.append(Note(group=group, text=description))

    def notes(self) -> list[str]:
        notes = [(f"real-time guard: kernel RT throttling {rt_throttling()}; watchdog demotes a group whose "
                  f"SCHED_FIFO threads (its own priority or a boost) keep a CPU busy for {WATCHDOG_LIMIT:g} s"),
                 *self.watch.notes()]
        if self.inheritance_note:
            notes.append(self.inheritance_note)
        if self.transport == "process":
            piped = sorted(f"{a}->{b}" for a, b in self.capacities if self.group_of.get(a) != self.group_of.get(b))
            if piped:
                notes.append(f"capacity not counted in messages on {', '.join(piped)}: between processes a channel "
                             "is a shared-memory ring, and its size (1 MiB) is what bounds it")
        return notes

    def bound(self, seconds: float) -> None:
        """Nothing to arm: the roles run in other processes, which the supervisor can always kill."""

    def close(self) -> None:
        self.watchdog.stop()
        self.watch.end()
        for name, inc in self.current.items():
            if inc.process is not None and inc.process.is_alive():
                self.kill(name)
        deadline = time.monotonic() + _CLOSE_WAIT  # one bound for all of them, not one each
        for inc in self.current.values():
            self._reap(inc, max(0.0, deadline - time.monotonic()))
            kill_remembered(inc.tree)
            if inc.cgroup is not None:
                inc.cgroup.remove()
            self._close(inc)
        remove_run_segments(self.run_id)
        if self.inheritance is not None:
            self.inheritance.release(list(self.group_of))
            self.boosts, self.inactive = self.inheritance.boosts(), self.inheritance.inactive()
            self.inheritance.close(unlink=True)

    def inheritance_report(self) -> tuple[dict[tuple[str, str], Boosts], list[str]]:
        """What priority inheritance did (per waiter->target), and the roles it was inactive for."""
        return self.boosts, self.inactive


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


def _sent_at(messages: Sequence[object], now: float) -> float:
    """When the group last proved alive: the send time of its latest heartbeat (data that sat
    unread in the pipe while the supervisor did not run is not silence), else now."""
    beats = [m.at for m in messages if isinstance(m, control.Beat)]
    if len(beats) < len(messages) or not all(isinstance(at, float) and math.isfinite(at) for at in beats):
        return now
    return min(now, max(beats))


def _pidfd(pid: int | None) -> int | None:
    """A descriptor that becomes readable when process ``pid`` exits (Linux 5.3+), else None."""
    if pid is None or not hasattr(os, "pidfd_open"):
        return None
    try:
        return os.pidfd_open(pid)
    except OSError:  # an older kernel, or seccomp: the sentinel it is
        return None


def _sys_path() -> list[str]:
    return [os.path.abspath(p) for p in sys.path]
