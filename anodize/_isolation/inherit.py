"""Priority inheritance over channels: a waiter lends its priority to the role it waits on.

One :class:`BoostTable` per run holds, for every role on this host, the threads that play it
(Linux thread ids: the role's thread, and the threads of its parallel branches once they
have waited in the session), each thread's own scheduling (SCHED_FIFO 1..99, or 0 for any
other policy) and the priority a boost has applied to it (0: none), whether the role's group
accepts boosts, and, per ordered pair of roles, how many waits of the first on the second
are blocked right now.

A waiter that is about to block (:meth:`BoostTable.waiting`) counts its wait, then *settles*
the table: every role's effective priority is the highest of its own and those of the roles
blocked on it, through chains (A waits on B which waits on C: C runs at A's priority), and
every thread whose effective priority changed gets one ``sched_setscheduler`` call. When
the wait ends (a message, a timeout, a failure, a stop) the waiter takes its count back and
settles again, which drops the boost at once. A role whose thread ends clears its entry
and restores its threads (:meth:`BoostTable.leave`); a group whose process died is cleared
by the supervisor (:meth:`BoostTable.release`). Who undoes a boost is therefore always
someone alive: the waiter, the ending thread, or the supervisor; a boost outlives none.

A role's boost goes to every thread registered for it: the role's thread (at its start) and
each thread of its parallel branches from its first blocking wait on (a branch thread that
never blocks is busy anyway); a helper thread that never calls the endpoint is never boosted.

Between threads the table lives in anonymous memory; between processes in a file under
``/dev/shm`` that the supervisor creates and every group maps (a threading lock plus
``flock`` serialise the settles). Per ordered pair (waiter, target) it counts the episodes
in which the target ran boosted and the time it did, which the supervisor reads at the end.

A waiter not under SCHED_FIFO (refused, or no priority asked) lends nothing: where the
fallback to nice values is in force, inheritance is inactive and the report says so.
"""

from __future__ import annotations

import contextlib
import fcntl
import mmap
import os
import threading
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

__all__ = ["BoostTable", "RoleSeat", "Boosts", "thread_priority", "inheritance_table"]

THREADS = 8  # threads per role the table can boost (the role's, and its parallel branches')
# Per role: accepts boosts, ran without SCHED_FIFO though its group asked for a priority, then per
# thread: thread id, policy, own priority (0: not FIFO), applied boost.
_INHERIT, _INACTIVE, _HEAD = 0, 1, 2
_TID, _POLICY, _BASE, _APPLIED = range(4)
_ROLE_FIELDS = _HEAD + 4 * THREADS


@dataclass(frozen=True)
class RoleSeat:
    """A role's place in the table: its group's priority (None: none asked) and whether its
    group accepts boosts (``priority_inheritance``)."""

    role: str
    priority: int | None
    inherit: bool


@dataclass(frozen=True)
class Boosts:
    """What inheritance did on one pair of roles: ``episodes`` waits in which the target ran
    boosted, ``seconds`` the time it did."""

    episodes: int
    seconds: float


def thread_priority(tid: int = 0) -> tuple[int, int]:
    """``(policy, priority)`` of thread ``tid`` (0: the calling thread); priority 0 unless FIFO/RR."""
    policy = os.sched_getscheduler(tid)
    priority = os.sched_getparam(tid).sched_priority if policy in (os.SCHED_FIFO, os.SCHED_RR) else 0
    return policy, priority


class BoostTable:
    """The run's inheritance table (see the module docstring).

    Create it with :meth:`create` (the supervisor, or the in-process runner), open it in a
    group process with :meth:`open`.
    """

    def __init__(self, seats: Sequence[RoleSeat], memory: mmap.mmap, fd: int | None, path: str | None) -> None:
        self.seats = tuple(seats)
        self.index = {seat.role: i for i, seat in enumerate(self.seats)}
        self.path = path
        self._fd = fd
        self._memory = memory
        count = len(self.seats)
        roles, pairs = count * _ROLE_FIELDS, count * count
        words = memoryview(memory).cast("q")
        self._words = words
        self._slots = words[:roles]
        self._active = words[roles:roles + pairs]  # blocked waits of i on j, now
        self._episodes = words[roles + pairs:roles + 2 * pairs]
        self._nanos = words[roles + 2 * pairs:roles + 3 * pairs]
        self._lock = threading.Lock()
        self._known: set[int] = set()  # this process's threads already registered (native ids)

    # ---- life cycle --------------------------------------------------------------------
    @staticmethod
    def _size(count: int) -> int:
        return max(8, 8 * (count * _ROLE_FIELDS + 3 * count * count))

    @classmethod
    def create(cls, seats: Sequence[RoleSeat], path: str | None = None) -> BoostTable:
        """A new table for ``seats``: in a file at ``path`` (shared with group processes) or in
        this process's memory."""
        size = cls._size(len(seats))
        fd = None
        if path is None:
            memory = mmap.mmap(-1, size)
        else:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o600)
            os.ftruncate(fd, size)
            memory = mmap.mmap(fd, size)
        table = cls(seats, memory, fd, path)
        for i, seat in enumerate(table.seats):
            table._slots[i * _ROLE_FIELDS + _INHERIT] = int(seat.inherit)
        return table

    @classmethod
    def open(cls, seats: Sequence[RoleSeat], path: str) -> BoostTable:
        """The table the supervisor created at ``path`` (``seats`` as it was given them)."""
        fd = os.open(path, os.O_RDWR)
        return cls(seats, mmap.mmap(fd, cls._size(len(seats))), fd, path)

    def close(self, unlink: bool = False) -> None:
        """Unmap the table (``unlink``: and remove its file: the supervisor, at the end)."""
        for view in (self._slots, self._active, self._episodes, self._nanos, self._words):
            view.release()
        with contextlib.suppress(BufferError):
            self._memory.close()
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if unlink and self.path is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.path)

    # ---- what roles do -------------------------------------------------------------------
    def enter(self, role: str) -> None:
        """The calling thread plays ``role`` from now on (its own priority is read now)."""
        i = self.index.get(role)
        if i is None:
            return
        with self._locked():
            self._slots[i * _ROLE_FIELDS + _INHERIT] = int(self.seats[i].inherit)  # (a demotion was the last one's)
            self._forget(i, restore=False)  # an earlier incarnation's threads are gone
            self._join(i)
            if self.seats[i].priority and not self._base(i):  # SCHED_FIFO was refused: a nice value
                self._slots[i * _ROLE_FIELDS + _INACTIVE] = 1
            self._settle()  # roles already waiting on it lend it their priority now

    def join(self, role: str) -> None:
        """The calling thread plays ``role`` too (a parallel branch's thread): boosts reach it."""
        i = self.index.get(role)
        if i is None or threading.get_native_id() in self._known:
            return
        with self._locked():
            self._join(i)
            self._settle()

    def leave(self, role: str) -> None:
        """The thread of ``role`` ends: what it lent is taken back, its threads run at their own
        priority again, and the table forgets them."""
        i = self.index.get(role)
        if i is None:
            return
        with self._locked():
            self._forget(i, restore=True)
            self._settle()

    def release(self, roles: Iterable[str]) -> None:
        """Forget ``roles``' threads, which are gone (their process died): boosts they lent end."""
        with self._locked():
            for role in roles:
                i = self.index.get(role)
                if i is not None:
                    self._forget(i, restore=False)
            self._settle()

    def demote(self, roles: Iterable[str]) -> None:
        """``roles``' threads were moved to SCHED_OTHER (the watchdog demoted their group): they
        are never boosted again in this incarnation, and lend nothing."""
        with self._locked():
            for role in roles:
                i = self.index.get(role)
                if i is None:
                    continue
                self._slots[i * _ROLE_FIELDS + _INHERIT] = 0
                for k in self._threads(i):
                    self._put(i, k, _POLICY, os.SCHED_OTHER)
                    self._put(i, k, _BASE, 0)
                    self._put(i, k, _APPLIED, 0)
            self._settle()

    def could_boost(self, waiter: str, target: str) -> bool:
        """Whether ``waiter``'s waits on ``target`` can ever lend it a priority (a static view from
        the groups' priorities: a chain can raise a waiter above its own group's)."""
        i, j = self.index.get(waiter), self.index.get(target)
        if i is None or j is None or i == j or not self.seats[j].inherit:
            return False
        seat, lower = self.seats[i], self.seats[j].priority or 0
        if (seat.priority or 0) > lower:
            return True
        # A waiter that is itself boosted (through a chain) passes on what it was lent.
        return seat.inherit and any((other.priority or 0) > lower for other in self.seats)

    @contextlib.contextmanager
    def waiting(self, waiter: str, *targets: str) -> Iterator[None]:
        """While the body runs (a blocking wait of the calling thread, which plays ``waiter``, on
        any of ``targets``), each target runs at least at ``waiter``'s priority."""
        i = self.index[waiter]
        count = len(self.seats)
        cells = [i * count + self.index[target] for target in targets]
        with self._locked():
            if threading.get_native_id() not in self._known:
                self._join(i)  # a parallel branch's thread, waiting for the first time
            for cell in cells:
                self._active[cell] += 1
            effective, own = self._settle()
            mine = effective[i]  # what this wait lends: the waiter's own priority, or what it was lent
            boosted = [cell for cell in cells if mine > own[cell % count] and effective[cell % count] >= mine]
        start = time.monotonic_ns() if boosted else 0
        try:
            yield
        finally:
            with self._locked():
                for cell in cells:
                    if self._active[cell] > 0:  # (a release may have cleared it)
                        self._active[cell] -= 1
                self._settle()
                if boosted:
                    spent = time.monotonic_ns() - start
                    for cell in boosted:
                        self._episodes[cell] += 1
                        self._nanos[cell] += spent

    # ---- what the supervisor reads ----------------------------------------------------
    def boosts(self) -> dict[tuple[str, str], Boosts]:
        """Per (waiter, target) with at least one episode: what inheritance did."""
        found = {}
        count = len(self.seats)
        for cell in range(count * count):
            episodes = self._episodes[cell]
            if episodes:
                waiter, target = self.seats[cell // count].role, self.seats[cell % count].role
                found[(waiter, target)] = Boosts(episodes, self._nanos[cell] / 1e9)
        return found

    def inactive(self) -> list[str]:
        """Roles whose group asked for a priority but whose thread is not under SCHED_FIFO: their
        waits lend nothing (the fallback to nice values is in force)."""
        return [seat.role for i, seat in enumerate(self.seats) if self._slots[i * _ROLE_FIELDS + _INACTIVE]]

    def applied(self, role: str) -> int:
        """The highest priority a boost has applied to one of ``role``'s threads now (0: none)."""
        i = self.index[role]
        return max((self._get(i, k, _APPLIED) for k in self._threads(i)), default=0)

    # ---- internals --------------------------------------------------------------------------
    def _get(self, i: int, k: int, what: int) -> int:
        return int(self._slots[i * _ROLE_FIELDS + _HEAD + 4 * k + what])

    def _put(self, i: int, k: int, what: int, value: int) -> None:
        self._slots[i * _ROLE_FIELDS + _HEAD + 4 * k + what] = value

    def _threads(self, i: int) -> list[int]:
        """The sub-slots of role ``i`` that hold a thread."""
        return [k for k in range(THREADS) if self._get(i, k, _TID)]

    def _base(self, i: int) -> int:
        """Role ``i``'s own priority: the highest of its threads' (0: none under SCHED_FIFO)."""
        return max((self._get(i, k, _BASE) for k in self._threads(i)), default=0)

    def _join(self, i: int) -> None:
        """Register the calling thread for role ``i`` (in a free sub-slot; none free: not boosted)."""
        tid = threading.get_native_id()
        free = [k for k in range(THREADS) if self._get(i, k, _TID) in (0, tid)]
        if not free:
            return
        policy, priority = thread_priority()
        k = free[0]
        self._put(i, k, _TID, tid)
        self._put(i, k, _POLICY, policy)
        self._put(i, k, _BASE, priority)
        self._put(i, k, _APPLIED, 0)
        self._known.add(tid)

    def _forget(self, i: int, restore: bool) -> None:
        """Clear role ``i``: its waits, and its threads (``restore``: back to their own priority)."""
        count = len(self.seats)
        for j in range(count):
            self._active[i * count + j] = 0
        for k in self._threads(i):
            tid = self._get(i, k, _TID)
            if restore and self._get(i, k, _APPLIED):
                with contextlib.suppress(OSError):  # the thread has already ended
                    os.sched_setscheduler(tid, self._get(i, k, _POLICY), os.sched_param(self._get(i, k, _BASE)))
            self._known.discard(tid)
            for what in (_TID, _POLICY, _BASE, _APPLIED):
                self._put(i, k, what, 0)

    @contextlib.contextmanager
    def _locked(self) -> Iterator[None]:
        with self._lock:
            if self._fd is None:
                yield
                return
            fcntl.flock(self._fd, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(self._fd, fcntl.LOCK_UN)

    def _settle(self) -> tuple[list[int], list[int]]:
        """Effective priorities through the chains of waits; one scheduling call per change.
        Returns each role's effective priority and its own (the table read once, as lists)."""
        count = len(self.seats)
        slots = self._slots.tolist()
        threads: list[list[int]] = []  # per role: where each of its threads' fields start
        own = [0] * count
        for i in range(count):
            start = i * _ROLE_FIELDS + _HEAD
            held = [start + 4 * k for k in range(THREADS) if slots[start + 4 * k + _TID]]
            threads.append(held)
            if held:
                own[i] = max(slots[at + _BASE] for at in held)
        effective = own[:]
        edges = []
        for cell, blocked in enumerate(self._active.tolist()):
            if blocked:
                i, j = divmod(cell, count)
                if threads[i] and threads[j] and slots[j * _ROLE_FIELDS + _INHERIT]:
                    edges.append((i, j))
        for _ in range(count):  # a chain is at most ``count`` long; a cycle cannot raise anything further
            changed = False
            for i, j in edges:
                if effective[i] > effective[j]:
                    effective[j] = effective[i]
                    changed = True
            if not changed:
                break
        for j in range(count):
            for at in threads[j]:
                base = slots[at + _BASE]
                want = effective[j] if effective[j] > base else 0
                if want == slots[at + _APPLIED]:
                    continue
                try:
                    if want:
                        os.sched_setscheduler(slots[at + _TID], os.SCHED_FIFO, os.sched_param(want))
                    else:
                        os.sched_setscheduler(slots[at + _TID], slots[at + _POLICY], os.sched_param(base))
                except OSError:  # the thread is gone, or the boost was refused: nothing is applied
                    want = 0
                self._slots[at + _APPLIED] = want
        return effective, own


class _Grouped(Protocol):
    @property
    def priority(self) -> int | None: ...

    @property
    def priority_inheritance(self) -> bool: ...

    @property
    def roles(self) -> Mapping[str, Any]: ...


def inheritance_table(groups: Iterable[_Grouped], path: str | None = None) -> BoostTable | None:
    """The table for a run of ``groups`` (at ``path`` for group processes), or None where no
    group has a priority (nothing runs under SCHED_FIFO: there is nothing to lend)."""
    groups = list(groups)
    if not any(group.priority for group in groups):
        return None
    return BoostTable.create([RoleSeat(role, group.priority, group.priority_inheritance)
                              for group in groups for role in group.roles], path)
