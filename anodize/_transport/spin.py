"""Spin then park: a receiver polls for a bounded, adaptive time before it sleeps.

Waking a sleeping process costs several microseconds of the kernel's work (the
wake-up, a context switch, often a CPU leaving an idle state); a round trip
between two processes pays it twice. A receiver that *polls* for a little while
before it sleeps takes a reply that comes within that while without any of it.
Polling burns the CPU it runs on, so it is worth it only for a group whose roles
answer fast, on a CPU of its own: a group asks for it in the system file
(``[groups.control] spin = "50us"``) or with ``System.group(spin=...)``.

The rule (one :class:`Spinner` per receiving channel, one :class:`SpinPolicy`
per group):

* **Grow when it paid off.** Data arriving after ``t`` of spinning sets the
  budget to at least ``2 t`` (headroom for the next one), at most the group's
  maximum.
* **Shrink when it did not.** A spin that ends with nothing halves the budget;
  below :data:`FLOOR` it becomes 0 and the receiver parks at once.
* **Probe now and then.** With a budget of 0, one wait in ``n`` spins for the
  full maximum (``n`` doubles after each probe that misses, up to
  :data:`PROBE_EVERY_MAX`, and is back to 1 after a hit): a peer that became
  fast again is noticed, a slow one costs at most ``maximum / 64`` a wait.
* **Never past the caller's deadline.** A receive with a timeout passes it as ``limit``:
  the spin ends by then, and a spin it cut short changes nothing.
* **Never more than a share of a CPU.** Every spin draws on the group's
  allowance, a bucket that fills at :data:`SHARE` of a CPU second per second up
  to :data:`BURST` seconds: however the peers behave, spinning keeps a CPU busy
  for at most about a quarter of any window, well below the real-time guard's
  limit (:mod:`anodize._isolation.watchdog` demotes a group that keeps a CPU
  90% busy for 0.5 s). A wait finding less than its budget in the allowance
  parks at once, without a shorter spin (one cut short would mostly end just
  before the data comes) and without shrinking the budget: the peer was not slow.

No ``sched_yield`` in the loop: a SCHED_FIFO receiver that spins has its CPU to
itself among the run's groups (the supervisor refuses spinning to one that shares a
CPU with another group), an ordinary one is preempted by the scheduler anyway, and
yielding to nobody only adds a system call per poll.

The counters (time spent spinning, waits that spun, wakes saved) are read for
the run report. Several threads of a group may share a policy: they update its
allowance without a lock, so a race can overdraw it by at most one budget per
thread (the bound above is approximate by that much).
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Mapping
from decimal import Decimal

from ..errors import ConfigurationError

__all__ = ["SpinPolicy", "Spinner", "parse_spin", "describe_spin", "spin_refusal", "SPIN_MAX", "FLOOR", "SHARE",
           "BURST", "PROBE_EVERY_MAX"]

SPIN_MAX = 1_000_000  # nanoseconds: a longer spin is a sleep that burns a CPU; park instead
FLOOR = 1e-6  # seconds: a budget below this is not worth a poll; it becomes 0
SHARE = 0.25  # of one CPU: what spinning may use on average (the allowance's fill rate)
BURST = 0.01  # seconds: the most the allowance holds (spinning after a quiet spell)
PROBE_EVERY_MAX = 64  # with a budget of 0: at most one wait in this many spins the full maximum

_NANOS = {"ns": 1, "us": 1_000, "µs": 1_000, "μs": 1_000, "ms": 1_000_000, "s": 1_000_000_000}
_DURATION = re.compile(r"\s*([0-9]+(?:\.[0-9]+)?)\s*(ns|us|µs|μs|ms|s)\s*")


def parse_spin(value: object) -> int:
    """A spin setting in nanoseconds (0: off): a duration as the protocol language writes them
    (``"50us"``, ``"0.2ms"``), or an int of microseconds; None and False are off.

    Raises:
        ConfigurationError: anything else, a negative one, or one over 1 ms.
    """
    if value is None or value is False:
        return 0
    if isinstance(value, int) and not isinstance(value, bool):
        nanos = value * 1_000
    elif isinstance(value, str) and (match := _DURATION.fullmatch(value)):
        nanos = int(Decimal(match[1]) * _NANOS[match[2]])  # the pattern admits only decimals
    else:
        shown = repr(value) if len(repr(value)) <= 40 else f"{repr(value)[:37]}..."
        raise ConfigurationError(f"spin {shown}: expected a duration such as \"50us\" or \"0.2ms\", "
                                 "or a number of microseconds")
    if nanos < 0:
        raise ConfigurationError(f"spin {value!r}: expected a duration >= 0")
    if nanos > SPIN_MAX:
        raise ConfigurationError(f"spin {value!r}: at most 1ms (a longer wait is cheaper asleep)")
    return nanos


def describe_spin(nanos: int) -> str:
    """``"50us"``, ``"1.5us"``: a spin setting as written back in messages and reports."""
    if nanos % 1000 == 0:
        return f"{nanos // 1000}us"
    return f"{nanos}ns"


def spin_refusal(priority: int | None, cpus: frozenset[int] | None,
                 others: Mapping[str, frozenset[int] | None]) -> str | None:
    """Why a group may not spin, or None: a SCHED_FIFO group (``priority``) spinning on a CPU
    another group may use keeps that group off it (the kernel runs no lower task while a FIFO
    thread is runnable), and its peer there cannot even send what it waits for.

    Args:
        priority: the group's priority (None: ordinary scheduling, which preempts a spinner).
        cpus: the group's CPUs (None: any).
        others: every other group's CPUs (None: any), by name.
    """
    if priority is None:
        return None
    sharing = sorted(name for name, theirs in others.items()
                     if cpus is None or theirs is None or cpus & theirs)
    if not sharing:
        return None
    where = "may run on any CPU" if cpus is None else f"cpus {sorted(cpus)}"
    return (f"SCHED_FIFO {priority} on {where}, which group{'s' if len(sharing) > 1 else ''} "
            f"{', '.join(sharing)} may also use: spinning there would starve {'them' if len(sharing) > 1 else 'it'}; "
            "give this group cpus no other group has")


class SpinPolicy:
    """A group's spinning: the maximum budget and the CPU allowance its receivers share.

    Args:
        maximum: the longest spin, in seconds (> 0).
        clock: seconds, monotonic and cheap (a test passes a fake one).
        share, burst: the allowance (see the module's docstring).
    """

    def __init__(self, maximum: float, clock: Callable[[], float] = time.perf_counter,
                 share: float = SHARE, burst: float = BURST) -> None:
        if not maximum > 0:
            raise ValueError(f"a spin policy needs a maximum > 0, got {maximum!r}")
        self.maximum = maximum
        self.clock = clock
        self.share = share
        self.burst = max(burst, maximum)  # room for one whole spin at least
        self._credit = self.burst
        self._filled_at = clock()
        self.spinners: list[Spinner] = []

    def spinner(self) -> Spinner:
        """A spinner for one receiving channel (one thread waits on it at a time)."""
        spinner = Spinner(self)
        self.spinners.append(spinner)
        return spinner

    def allowance(self, now: float) -> float:
        """Seconds of spinning the group may spend now."""
        credit = self._credit + (now - self._filled_at) * self.share
        self._filled_at = now
        self._credit = credit = min(credit, self.burst)
        return credit

    def charge(self, spent: float) -> None:
        """``spent`` seconds of spinning were used."""
        self._credit -= spent

    @property
    def spun(self) -> float:
        """Seconds spent spinning, by every receiver of the group."""
        return sum(s.spun for s in self.spinners)

    @property
    def saved(self) -> int:
        """Wakes saved: waits in which data came while spinning."""
        return sum(s.saved for s in self.spinners)

    @property
    def spins(self) -> int:
        """Waits that spun (saved or not)."""
        return sum(s.spins for s in self.spinners)

    def summary(self) -> str:
        """The cost and the gain, for the run report."""
        spins, saved = self.spins, self.saved
        share = f" ({saved / spins:.0%})" if spins else ""
        return (f"spinning used {self.spun * 1e3:.1f} ms of CPU in {spins} waits; "
                f"{saved} wakes saved{share}")


class Spinner:
    """Spin, then park, for one receiving channel; the budget adapts (see the module's docstring).

    Attributes:
        budget: seconds the next wait spins (0: it parks at once, but for probes).
        spun: seconds spent spinning so far.
        spins: waits that spun.
        saved: waits in which data came while spinning (a wake saved).
    """

    def __init__(self, policy: SpinPolicy) -> None:
        self.policy = policy
        self.budget = policy.maximum
        self.spun = 0.0
        self.spins = 0
        self.saved = 0
        self._skip = 0  # with a budget of 0: waits to park at once before the next probe
        self._probe_every = 1

    def wait(self, ready: Callable[[], bool], limit: float | None = None) -> bool:
        """Poll ``ready()`` for up to the current budget; True as soon as it is (the caller then
        reads without sleeping), False when the budget ran out (the caller sleeps as before).

        ``limit``: the caller's own deadline, in seconds from now (a receive with a timeout): the
        spin never outlasts it, and a spin it cut short teaches nothing about the peer.
        """
        policy = self.policy
        budget = self.budget
        if budget <= 0:
            if self._skip:
                self._skip -= 1
                return False
            budget = policy.maximum  # a probe
        clock = policy.clock
        start = clock()
        if policy.allowance(start) < budget:
            # Too little left for a whole spin: park, and learn nothing about the peer. A spin cut
            # short would mostly end just before the data comes: CPU spent for no wake saved.
            return False
        limited = limit is not None and limit < budget
        if limit is not None and limited:
            budget = limit
        deadline = start + budget
        self.spins += 1
        while True:
            if ready():
                spent = clock() - start
                self._account(spent)
                self.saved += 1
                self.budget = min(policy.maximum, max(self.budget, 2 * spent, FLOOR))
                self._probe_every = 1
                return True
            now = clock()
            if now >= deadline:
                break
        self._account(now - start)
        if not limited:
            self._missed()
        return False

    def _account(self, spent: float) -> None:
        self.spun += spent
        self.policy.charge(spent)

    def _missed(self) -> None:
        if self.budget <= 0:  # a probe that missed: probe less often
            self._probe_every = min(self._probe_every * 2, PROBE_EVERY_MAX)
            self._skip = self._probe_every - 1
            return
        self.budget /= 2
        if self.budget < FLOOR:
            self.budget = 0.0
            self._skip = self._probe_every - 1
