"""The kernel's view of a process, read from ``/proc``: is it stopped, does it get the CPU,
is it waiting for one.

Three numbers tell a frozen group from a starved one (see
:mod:`anodize._supervision.liveness`): the scheduler state of its threads
(``/proc/<pid>/task/<tid>/stat``: ``T``/``t`` is stopped), the CPU time the process
has used (utime + stime of all its threads, ``/proc/<pid>/stat``), and how long each
thread has waited on a run queue while runnable (the second field of
``/proc/<pid>/task/<tid>/schedstat``, nanoseconds; time spent throttled by a cgroup's
CPU quota counts too). Everything here returns ``None`` (or an empty answer) where
``/proc`` does not say, so callers fall back to what heartbeats alone show.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass

__all__ = ["ProcSample", "sample", "cpu_seconds", "thread_times", "own_run_delay", "rivals", "machine_load",
           "cpu_quota"]

_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


@dataclass(frozen=True)
class ProcSample:
    """One look at a process.

    Attributes:
        at: ``time.monotonic()`` when it was read.
        cpu: seconds of CPU (user + system) the process has used, all its threads.
        waited: per thread id, seconds it has spent runnable on a run queue, not running. The
            kernel adds a wait when it ends: a thread still waiting has not been counted yet.
        ran: per thread id, seconds it has run on a CPU.
        slices: per thread id, how many times it has been put on a CPU.
        states: per thread id, its scheduler state letter (``R``, ``S``, ``D``, ``T``, ...).
        cpus: the CPUs its threads last ran on.
    """

    at: float
    cpu: float
    waited: dict[int, float]
    ran: dict[int, float]
    slices: dict[int, int]
    states: dict[int, str]
    cpus: frozenset[int]

    @property
    def stopped(self) -> bool:
        """Whether any of its threads is stopped (SIGSTOP, or traced by a debugger)."""
        return any(state in "Tt" for state in self.states.values())


def _stat_fields(path: str) -> list[str] | None:
    """The fields of a ``stat`` file after the command name (field 3, the state, first)."""
    try:
        with open(path) as f:
            return f.read().rpartition(")")[2].split()
    except OSError:
        return None


def _schedstat(path: str) -> tuple[float, float, int] | None:
    """(seconds run on a CPU, seconds waited on a run queue, times put on a CPU) from a
    ``schedstat`` file."""
    try:
        with open(path) as f:
            ran, waited, slices = f.read().split()[:3]
        return int(ran) / 1e9, int(waited) / 1e9, int(slices)
    except (OSError, ValueError):
        return None


def _run_delay(path: str) -> float | None:
    times = _schedstat(path)
    return None if times is None else times[1]


def _cpu(fields: list[str]) -> float:
    return (int(fields[11]) + int(fields[12])) / _TICKS  # utime, stime: fields 14 and 15 of stat(5)


def cpu_seconds(pid: int) -> float | None:
    """CPU time (user + system) the process has used, all threads; None if it is gone."""
    fields = _stat_fields(f"/proc/{pid}/stat")
    return None if fields is None or len(fields) < 13 else _cpu(fields)


def thread_times(pid: int) -> dict[int, tuple[float, bool]] | None:
    """Per thread of ``pid``: the CPU time it has used and whether it runs under a real-time
    policy (SCHED_FIFO or SCHED_RR) now; None if the process is gone."""
    try:
        tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except OSError:
        return None
    times: dict[int, tuple[float, bool]] = {}
    for tid in tids:
        fields = _stat_fields(f"/proc/{pid}/task/{tid}/stat")
        if fields is not None and len(fields) > 38:  # field 41, policy
            times[tid] = (_cpu(fields), int(fields[38]) in (os.SCHED_FIFO, os.SCHED_RR))
    return times


def sample(pid: int) -> ProcSample | None:
    """Read ``pid``'s state, CPU time and its threads' run-queue waits; None if it is gone."""
    at = time.monotonic()
    fields = _stat_fields(f"/proc/{pid}/stat")
    if fields is None or len(fields) < 13:
        return None
    cpu = _cpu(fields)
    waited: dict[int, float] = {}
    ran: dict[int, float] = {}
    slices: dict[int, int] = {}
    states: dict[int, str] = {}
    cpus: set[int] = set()
    try:
        tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except OSError:
        tids = []
    for tid in tids:
        task = _stat_fields(f"/proc/{pid}/task/{tid}/stat")
        times = _schedstat(f"/proc/{pid}/task/{tid}/schedstat")
        if task is None or times is None:
            continue  # the thread ended between the listing and the read
        states[tid] = task[0]
        ran[tid], waited[tid], slices[tid] = times
        if len(task) > 36:
            cpus.add(int(task[36]))  # field 39, processor: the CPU it last ran on
    if not states:
        states[pid] = fields[0]
    return ProcSample(at=at, cpu=cpu, waited=waited, ran=ran, slices=slices, states=states, cpus=frozenset(cpus))


def own_run_delay() -> float | None:
    """Seconds the calling thread has spent runnable but not running (None where unknown)."""
    return _run_delay(f"/proc/self/task/{threading.get_native_id()}/schedstat")


def machine_load() -> str:
    """``"the machine: load 3.1 on 2 CPUs"`` (the one-minute load average)."""
    try:
        with open("/proc/loadavg") as f:
            load = float(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return f"the machine ({os.cpu_count() or '?'} CPUs, load unknown)"
    return f"the machine: load {load:.1f} on {os.cpu_count() or '?'} CPUs"


def cpu_quota(pid: int) -> str | None:
    """``"its cgroup's CPU quota (1 ms per 1000 ms)"`` when ``pid``'s cpu cgroup (v1 ``cpu`` or
    v2) caps its CPU time, else None."""
    try:
        with open(f"/proc/{pid}/cgroup") as f:
            own = {controller: path for line in f
                   for _, controllers, path in [line.rstrip("\n").split(":", 2)]
                   for controller in (controllers.split(",") if controllers else [""])}
    except (OSError, ValueError):
        return None
    quota: tuple[int, int] | None = None
    try:
        if "cpu" in own:
            base = os.path.join("/sys/fs/cgroup/cpu", own["cpu"].lstrip("/"))
            with open(os.path.join(base, "cpu.cfs_quota_us")) as q, open(os.path.join(base, "cpu.cfs_period_us")) as p:
                quota = int(q.read()), int(p.read())
        elif "" in own:
            with open(os.path.join("/sys/fs/cgroup", own[""].lstrip("/"), "cpu.max")) as m:
                limit, period = m.read().split()
                quota = (-1 if limit == "max" else int(limit)), int(period)
    except (OSError, ValueError):
        return None
    if quota is None or quota[0] < 0:
        return None
    return f"its cgroup's CPU quota ({quota[0] / 1000:g} ms per {quota[1] / 1000:g} ms)"


def rivals(cpus: frozenset[int], exclude: int, most: int = 3) -> list[str]:
    """The runnable tasks (not of process ``exclude``) on ``cpus`` most likely to hold them:
    real-time ones first (by priority), then by CPU time used; e.g.
    ``"spin (pid 812, SCHED_FIFO 50)"``. Empty where ``/proc`` does not say.

    It scans every task of the machine, so call it once per episode, not per sample.
    """
    found: list[tuple[int, float, str]] = []
    try:
        pids = [p for p in os.listdir("/proc") if p.isdigit() and int(p) != exclude]
    except OSError:
        return []
    own = os.getpid()
    for pid in pids:
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tids:
            fields = _stat_fields(f"/proc/{pid}/task/{tid}/stat")
            if fields is None or len(fields) < 39 or fields[0] != "R" or int(pid) == own:
                continue
            if cpus and int(fields[36]) not in cpus:
                continue
            rt = int(fields[37])  # field 40, rt_priority: 0 for ordinary tasks
            nice = int(fields[16])  # field 19
            name = _command(pid, tid)
            how = f"SCHED_FIFO/RR {rt}" if rt else f"nice {nice}"
            used = (int(fields[11]) + int(fields[12])) / _TICKS
            found.append((rt, used, f"{name} (pid {pid}, {how})"))
    found.sort(key=lambda item: (item[0], item[1]), reverse=True)
    return [text for _, _, text in found[:most]]


def _command(pid: str, tid: str) -> str:
    try:
        with open(f"/proc/{pid}/task/{tid}/comm") as f:
            return f.read().strip()
    except OSError:
        return "?"
