"""The runner of ``Inproc``: every role is a thread of this process.

Groups started together share one :class:`~anodize._transport.inproc.InprocNetwork`;
a group restarted later gets a fresh network with the groups restarted with it,
where roles of the others are dead. Threads cannot be killed: a group the
supervisor ends is told to stop, and a role that does not reach its endpoint
within the grace period is abandoned (its thread runs on as a daemon, and the
report says where it still runs).

A role in a call that holds the GIL (a C extension, a backtracking regular
expression) keeps every other thread of the process from running, the
supervisor's included: the run returns once the call gives the GIL back, and
no sooner. The runner measures how long its own loop was held up that way and
says so in the run's notes; only ``Processes()`` can end such a call. A call that
never gives it back meets the last resort (:meth:`ThreadRunner.bound`): the
process exits with every thread's stack on stderr, 10 s after the run's timeout
and grace, rather than hang.
"""

from __future__ import annotations

import faulthandler
import os
import sys
import sysconfig
import threading
import time
from collections.abc import Callable, Sequence
from queue import Empty, SimpleQueue
from typing import Any

from .._isolation.inherit import Boosts, inheritance_table
from .._isolation.procstat import own_run_delay
from .._session.clock import adopt_clocks
from .._session.endpoint import Endpoint
from .._session.logs import LogCapture
from .._transport.inproc import InprocNetwork
from .._transport.spin import describe_spin
from ..taps import GroupTap
from .events import Counts, Event, GroupExited, Logged, Note, Ready, RoleEnded
from .group import Group, resolve_function
from .plan import RunPlan
from .report import RoleReport, RoleStatus, constraint_counts
from .roles import describe_error, run_role
from .runner import Scope

__all__ = ["ThreadRunner"]

_ABANDONED = ("did not stop within the grace period and is still running{where}, abandoned in its daemon "
              "thread: a thread cannot be killed, and a call that holds the GIL cannot even be interrupted "
              "in-process (transport=Processes() kills such a role's process)")
HELD_UP = 0.5  # seconds the runner's loop may wake late before it counts as held up by a role
LAST_RESORT = 10.0  # seconds past a run's timeout and grace before a process held by the GIL is ended
# The standard library's and anodize's own files: where a role is stuck is the role's code that called them.
_NOT_THE_ROLES = (sysconfig.get_paths()["stdlib"] + os.sep, os.path.dirname(os.path.dirname(__file__)) + os.sep)


class _Incarnation:
    """One start of one group: its endpoints, threads and what they reported."""

    def __init__(self, group: Group, number: int, network: InprocNetwork,
                 endpoints: dict[str, Endpoint]) -> None:
        self.group = group
        self.number = number
        self.network = network
        self.endpoints = endpoints
        self.gate = threading.Event()
        self.reported: set[str] = set()
        self.threads: dict[str, threading.Thread] = {}
        self.over = False


class ThreadRunner:
    """Starts groups as threads; see the module docstring."""

    transport = "inproc"

    def __init__(self, plan: RunPlan) -> None:
        self.plan = plan
        self.protocol = plan.protocol
        self.capacities = dict(plan.capacities or {})
        self.machines = dict(plan.machines)
        self.channels = tuple(plan.channels)
        self.groups = dict(plan.groups)
        self.monitors = plan.monitors
        self.group_of = {role: g.name for g in self.groups.values() for role in g.roles}
        self.scope = Scope(self.groups, tuple(r for r in plan.global_type.roles if r in self.group_of), self.channels)
        self.current: dict[str, _Incarnation] = {}
        self.inbox: SimpleQueue[Event] = SimpleQueue()
        self.taps: list[GroupTap] = []  # every group's taps, closed at the end of the run
        self.inheritance = inheritance_table(self.groups.values())
        self.boosts: dict[tuple[str, str], Boosts] = {}
        self.inactive: list[str] = []
        self.held_up: list[float] = []  # each time the loop woke HELD_UP late or more: by how much
        self.armed = False  # the last resort's timer (see bound)
        self.logs = LogCapture(self.group_of)  # the roles' records (this process's root level stays the caller's)
        self.logs.install()

    def start(self, groups: Sequence[str], incarnation: int) -> None:
        batch = set(groups)
        roles = {role for name in batch for role in self.groups[name].roles}
        channels = [(a, b) for a, b in self.channels if a in roles or b in roles]
        dead = {role: f"group {self.group_of[role]} did not start again with group(s) {', '.join(sorted(batch))}"
                for pair in channels for role in pair if role not in roles}
        # A doorbell for each role that may wait on several peers at once (recv_any).
        doorbells = [r for r in roles if self.machines[r].forks or self.machines[r].waits_on_several()]
        network = InprocNetwork(channels, doorbells, dead, self.capacities)
        network.inheritance = self.inheritance
        for name in groups:
            group = self.groups[name]
            for tap_plan in self.plan.taps:  # before the endpoints take their channels
                tap = tap_plan.open(self.plan.tap_group(group, incarnation))
                tap.attach(network.queues)
                adopt_clocks(network, tap)  # a recording records its roles' clock readings
                self.taps.append(tap)
            endpoints = {role: Endpoint(role, self.protocol, self.machines[role], network, self.monitors)
                         for role in group.roles}
            inc = self.current[name] = _Incarnation(group, incarnation, network, endpoints)
            for role, function in group.roles.items():
                target = resolve_function(function) if isinstance(function, str) else function
                thread = inc.threads[role] = threading.Thread(
                    target=self._role_thread, name=f"anodize:{name}/{role}", daemon=True, args=(inc, role, target))
                thread.start()
            self.inbox.put(Ready(group=name, incarnation=incarnation))
            if group.spin:  # a polling thread would hold the interpreter's lock its sending peer needs
                self.inbox.put(Note(group=name, text=f"spin {describe_spin(group.spin)} not used: roles of one "
                                                     "process (Inproc) wait on their queues"))

    def _role_thread(self, inc: _Incarnation, role: str, function: Callable[..., Any]) -> None:
        inc.gate.wait()
        group = inc.group

        def report(role_report: RoleReport) -> None:
            # The supervisor hears of a failure before the peers do: the root cause, not the
            # peers' PeerFailedErrors, is then what its policy acts on.
            self.inbox.put(RoleEnded(group=group.name, incarnation=inc.number, report=role_report))
            if role_report.status is RoleStatus.FAILED:
                inc.network.fail(role, describe_error(role_report.error))

        run_role(group.name, group.priority, group.cpus, role, function, inc.endpoints[role], report,
                 inheritance=self.inheritance, nice=group.nice, params=(self.plan.params or {}).get(role))

    def go(self, group: str) -> None:
        self.current[group].gate.set()

    def events(self, timeout: float) -> list[Event]:
        found: list[Event] = []
        asked = time.monotonic() + timeout
        queued = own_run_delay()
        try:
            found.append(self.inbox.get(timeout=timeout))
            while True:
                found.append(self.inbox.get_nowait())
        except Empty:
            pass
        late = time.monotonic() - asked
        if not found and late >= HELD_UP:  # no event woke it, and it did not run when it asked to
            after = own_run_delay()
            if queued is not None and after is not None:
                late -= after - queued  # waiting for a CPU is the machine's doing; what is left, the GIL's
            if late >= HELD_UP:
                self.held_up.append(late)
        for event in found:
            if isinstance(event, RoleEnded):
                inc = self.current[event.group]
                if inc.number == event.incarnation:
                    inc.reported.add(event.report.name)
        found.extend(self._counts())
        entries, dropped = self.logs.drain()
        if entries or dropped:
            found.append(Logged(entries=tuple(entries), dropped=dropped))
        for name, inc in self.current.items():
            if not inc.over and len(inc.reported) == len(inc.group.roles):
                inc.over = True
                found.append(GroupExited(group=name, incarnation=inc.number))
        return found

    def _counts(self) -> list[Event]:
        counts: list[Event] = []
        for name, inc in self.current.items():
            if inc.over:
                continue
            statistics = {role: ep.statistics() for role, ep in inc.endpoints.items()}
            sent = {f"{role}->{peer}": n for role, st in statistics.items() for peer, n in st.sent.items()}
            received = {f"{peer}->{role}": n for role, st in statistics.items() for peer, n in st.received.items()}
            waiting = {f"{role}->{peer}": n for role, st in statistics.items() for peer, n in st.high_water.items()}
            checked, closest, timeouts = constraint_counts(statistics)
            counts.append(Counts(group=name, incarnation=inc.number, at=time.monotonic(), sent=sent,
                                 received=received, waiting=waiting, checked=checked, closest=closest,
                                 timeouts=timeouts))
        return counts

    def tell_failed(self, group: str, role: str, cause: str) -> None:
        self.current[group].network.fail(role, cause)

    def stop(self, group: str) -> None:
        inc = self.current[group]
        inc.gate.set()  # a group stopped before "go" must still end
        inc.network.stop_roles(inc.group.roles)

    def kill(self, group: str) -> None:
        """Stop the group's roles; those that do not report are abandoned, not waited for."""
        inc = self.current[group]
        if inc.over:
            return
        self.stop(group)
        inc.over = True
        stuck = {role: _ABANDONED.format(where=_where(thread)) for role, thread in inc.threads.items()
                 if role not in inc.reported}
        self.inbox.put(GroupExited(group=group, incarnation=inc.number, details=stuck,
                                   unreported=_ABANDONED.format(where="") if stuck else ""))

    def notes(self) -> list[str]:
        if not self.held_up:
            return []
        return [(f"the supervisor was held up {len(self.held_up)} times (longest {max(self.held_up):.1f} s) by a "
                "role in a call that holds the GIL: the timeout and the grace period were late by as much, "
                "and a call that never gives the GIL back keeps the run from returning at all "
                "(transport=Processes() fails and kills such a group)")]

    def bound(self, seconds: float) -> None:
        """Arm the last resort: a role in a call that never gives the GIL back keeps every
        thread of this process from running, the supervisor's too, so nothing written in
        Python can end the run. ``faulthandler``'s timer is a thread of C that needs no GIL:
        if the run has not ended :data:`LAST_RESORT` seconds after its timeout and grace, it
        prints every thread's stack (the stuck role's frame among them) to stderr and exits
        the process with status 1. A run that ends disarms it."""
        try:  # to the process's own stderr (descriptor 2), whatever sys.stderr was replaced with
            faulthandler.dump_traceback_later(seconds + LAST_RESORT, exit=True, file=2)
            self.armed = True
        except (OSError, ValueError):  # no descriptor 2: the run is still bounded by its own loop
            pass

    def close(self) -> None:
        if self.armed:
            faulthandler.cancel_dump_traceback_later()
            self.armed = False
        for name in self.current:
            self.kill(name)
        for tap in self.taps:
            tap.close()
        self.logs.uninstall()  # an abandoned role's later records are nobody's
        if self.inheritance is not None:
            self.boosts, self.inactive = self.inheritance.boosts(), self.inheritance.inactive()

    def inheritance_report(self) -> tuple[dict[tuple[str, str], Boosts], list[str]]:
        """What priority inheritance did (per waiter->target), and the roles it was inactive for."""
        return self.boosts, self.inactive


def _where(thread: threading.Thread) -> str:
    """Where ``thread`` runs now: its innermost frame in the role's own code (not the standard
    library's, not anodize's), else its innermost frame; "" if it has ended."""
    frame = sys._current_frames().get(thread.ident or -1)
    innermost = frame
    while frame is not None and frame.f_code.co_filename.startswith(_NOT_THE_ROLES):
        frame = frame.f_back
    frame = frame or innermost
    if frame is None:
        return ""
    return f" (at {frame.f_code.co_filename}:{frame.f_lineno} in {frame.f_code.co_name})"
