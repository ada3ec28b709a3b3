"""Priority inheritance over channels: a waiter lends its priority to the role it waits on.

One :class:`BoostTable` per run (per batch of groups started together) holds, for every role
on this host, the thread that plays it (its Linux thread id), the priority it runs at of its
own (SCHED_FIFO 1..99, or 0 for any other policy), whether its group accepts boosts, which
role it is waiting on right now, and the priority a boost has applied to it (0: none).

A waiter that is about to block (:meth:`BoostTable.waiting`) writes whom it waits on, then
*settles* the table: every role's effective priority is the highest of its own and those of
the roles waiting on it, through chains (A waits on B which waits on C: C runs at A's
priority), and every thread whose effective priority changed gets one ``sched_setscheduler``
call. When the wait ends (message, timeout, failure, stop) the waiter clears its entry and
settles again, which drops the boost at once. A role whose thread ends clears its own entry
(:meth:`BoostTable.leave`); a group whose process dies is cleared by the supervisor
(:meth:`BoostTable.release`). Who undoes a boost is therefore always someone alive: the
waiter, the ending thread, or the supervisor; a boost outlives none of them.

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

# Per role: thread id, own FIFO priority (0: not FIFO), own policy, accepts boosts,
# waits on (role index or -1), applied boost (0: none), static (group) priority.
_TID, _BASE, _POLICY, _INHERIT, _WAITS, _APPLIED, _STATIC = range(7)
_FIELDS = 7


@dataclass(frozen=True)
class RoleSeat:
    """A role's place in the table: its group's priority (None: none asked) and whether its
    group accepts boosts (``priority_inheritance``)."""

    role: str
    priority: int | None
    inherit: bool


@dataclass(frozen=True)
class Boosts:
    """What inheritance did on one channel: ``episodes`` waits in which the target ran boosted,
    ``seconds`` the time it did."""

    episodes: int
    seconds: float


def thread_priority(tid: int = 0) -> tuple[int, int]:
    """``(policy, priority)`` of thread ``tid`` (0: the calling thread); priority 0 unless FIFO/RR."""
    policy = os.sched_getscheduler(tid)
    priority = os.sched_getparam(tid).sched_priority if policy in (os.SCHED_FIFO, os.SCHED_RR) else 0
    return policy, priority


class BoostTable:
    """The run's inheritance table (see the module docstring).

    Create it with :meth:`create` (the supervisor), open it in a group process with
    :meth:`open`; between threads :meth:`create` with no path is enough.
    """

    def __init__(self, seats: Sequence[RoleSeat], memory: mmap.mmap, fd: int | None, path: str | None) -> None:
        self.seats = tuple(seats)
        self.index = {seat.role: i for i, seat in enumerate(self.seats)}
        self.path = path
        self._fd = fd
        self._memory = memory
        count = len(self.seats)
        words = memoryview(memory).cast("q")
        self._words = words
        self._slots = words[: count * _FIELDS]
        self._episodes = words[count * _FIELDS: count * _FIELDS + count * count]
        self._nanos = words[count * _FIELDS + count * count: count * _FIELDS + 2 * count * count]
        self._lock = threading.Lock()

    # ---- life cycle --------------------------------------------------------------------
    @staticmethod
    def _size(count: int) -> int:
        return 8 * (count * _FIELDS + 2 * count * count)

    @classmethod
    def create(cls, seats: Sequence[RoleSeat], path: str | None = None) -> BoostTable:
        """A new table for ``seats``: in a file at ``path`` (shared with group processes) or in
        this process's memory."""
        size = cls._size(len(seats))
        fd = None
        if path is None:
            memory = mmap.mmap(-1, max(size, 8))
        else:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o600)
            os.ftruncate(fd, max(size, 8))
            memory = mmap.mmap(fd, max(size, 8))
        table = cls(seats, memory, fd, path)
        for i, seat in enumerate(table.seats):
            table._put(i, _WAITS, -1)
            table._put(i, _INHERIT, int(seat.inherit))
            table._put(i, _STATIC, seat.priority or 0)
        return table

    @classmethod
    def open(cls, seats: Sequence[RoleSeat], path: str) -> BoostTable:
        """The table the supervisor created at ``path`` (``seats`` as it was given them)."""
        fd = os.open(path, os.O_RDWR)
        return cls(seats, mmap.mmap(fd, max(cls._size(len(seats)), 8)), fd, path)

    def close(self, unlink: bool = False) -> None:
        """Unmap the table (``unlink``: and remove its file: the supervisor, at the end)."""
        for view in (self._slots, self._episodes, self._nanos, self._words):
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
        policy, priority = thread_priority()
        with self._locked():
            self._put(i, _TID, threading.get_native_id())
            self._put(i, _POLICY, policy)
            self._put(i, _BASE, priority)
            self._put(i, _APPLIED, 0)
            self._put(i, _WAITS, -1)
            self._settle()  # roles already waiting on it lend it their priority now

    def leave(self, role: str) -> None:
        """The thread of ``role`` ends: what it lent is taken back."""
        self.release([role])

    def release(self, roles: Sequence[str]) -> None:
        """Forget ``roles``' threads (ended, or their process died): boosts they lent or held end."""
        with self._locked():
            for role in roles:
                i = self.index.get(role)
                if i is not None:
                    self._put(i, _WAITS, -1)
                    self._put(i, _TID, 0)
                    self._put(i, _APPLIED, 0)
            self._settle()

    def could_boost(self, waiter: str, target: str) -> bool:
        """Whether ``waiter``'s waits on ``target`` can ever lend it a priority (static view: a
        chain can still raise a target at or above the waiter's own group)."""
        i, j = self.index.get(waiter), self.index.get(target)
        if i is None or j is None or i == j:
            return False
        seat, lower = self.seats[i], self.seats[j].priority or 0
        if not self.seats[j].inherit:
            return False
        if (seat.priority or 0) > lower:
            return True
        # A waiter that is itself boosted (through a chain) passes on what it was lent.
        return seat.inherit and any((seat.priority or 0) > lower for seat in self.seats)

    @contextlib.contextmanager
    def waiting(self, waiter: str, target: str) -> Iterator[None]:
        """While the body runs (a blocking wait), ``target`` runs at least at ``waiter``'s priority."""
        i, j = self.index[waiter], self.index[target]
        with self._locked():
            self._put(i, _WAITS, j)
            self._settle()
            boosted = self._get(j, _APPLIED) > 0 and self._effective_of(i) > self._get(j, _BASE)
        start = time.monotonic_ns() if boosted else 0
        try:
            yield
        finally:
            with self._locked():
                if self._get(i, _WAITS) == j:
                    self._put(i, _WAITS, -1)
                self._settle()
                if boosted:
                    cell = i * len(self.seats) + j
                    self._episodes[cell] += 1
                    self._nanos[cell] += time.monotonic_ns() - start

    # ---- what the supervisor reads ----------------------------------------------------
    def boosts(self) -> dict[tuple[str, str], Boosts]:
        """Per (waiter, target) with at least one episode: what inheritance did."""
        found = {}
        count = len(self.seats)
        for i in range(count):
            for j in range(count):
                episodes = self._episodes[i * count + j]
                if episodes:
                    found[(self.seats[i].role, self.seats[j].role)] = Boosts(
                        episodes, self._nanos[i * count + j] / 1e9)
        return found

    def inactive(self) -> list[str]:
        """Roles whose group asked for a priority but whose thread is not under SCHED_FIFO: their
        waits lend nothing (the fallback to nice values is in force)."""
        return [seat.role for i, seat in enumerate(self.seats)
                if seat.priority and self._get(i, _TID) and not self._get(i, _BASE)]

    def applied(self, role: str) -> int:
        """The priority a boost has applied to ``role``'s thread now (0: none)."""
        return self._get(self.index[role], _APPLIED)

    # ---- internals --------------------------------------------------------------------------
    def _get(self, i: int, what: int) -> int:
        return int(self._slots[i * _FIELDS + what])

    def _put(self, i: int, what: int, value: int) -> None:
        self._slots[i * _FIELDS + what] = value

    def _effective_of(self, i: int) -> int:
        return max(self._get(i, _BASE), self._get(i, _APPLIED))

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

    def _settle(self) -> None:
        """Effective priorities through the chains of waits; one scheduling call per change."""
        count = len(self.seats)
        live = [self._get(i, _TID) != 0 for i in range(count)]
        effective = [self._get(i, _BASE) if live[i] else 0 for i in range(count)]
        for _ in range(count):  # a chain is at most ``count`` long; a cycle cannot raise anything further
            changed = False
            for i in range(count):
                j = self._get(i, _WAITS)
                if (j >= 0 and live[i] and live[j] and self._get(j, _INHERIT)
                        and effective[i] > effective[j]):
                    effective[j] = effective[i]
                    changed = True
            if not changed:
                break
        for j in range(count):
            if not live[j]:
                continue
            base = self._get(j, _BASE)
            want = effective[j] if effective[j] > base else 0
            if want == self._get(j, _APPLIED):
                continue
            tid = self._get(j, _TID)
            try:
                if want:
                    os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(want))
                else:
                    policy = self._get(j, _POLICY)
                    os.sched_setscheduler(tid, policy, os.sched_param(base))
            except OSError:  # the thread is gone, or the boost was refused: nothing is applied
                want = 0
            self._put(j, _APPLIED, want)


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
