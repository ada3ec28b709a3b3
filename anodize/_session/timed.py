"""The run-time form of a machine's time and value constraints: what :class:`Monitor` checks.

Built once per monitor from its state machine (``sessiontypes.fsm``): a :class:`Rule` for each
transition that carries a constraint, or that must be seen by the monitor for another one to be
checked later (it leads to a state with a deadline, whose previous action is then time-stamped;
its record payload has a field an later refinement reads). Every other transition has no rule,
and the monitor's step for it is the one it always was: roles without constraints pay nothing.

Times are whole nanoseconds of the role's own clock (``Endpoint.now()``, seconds as a float),
converted once per reading by :func:`to_nanos`.
"""

from __future__ import annotations

from sessiontypes import StateMachine, Transition
from sessiontypes.constraints import Binary, Call, Compare, Expr, Path, Timing, Unary
from sessiontypes.refine import Predicate, compile_predicate, print_expr

from .predicates import FastCheck, fast_predicate
from .statistics import ConstraintCheck

__all__ = ["Rule", "Plan", "to_nanos", "format_nanos", "plan_for", "constraint_location"]

_NANOS_PER_SECOND = 1_000_000_000


def to_nanos(seconds: float) -> int:
    """A clock reading in seconds as whole nanoseconds (rounded: a float's last bits are noise)."""
    return round(seconds * _NANOS_PER_SECOND)


def format_nanos(nanos: int) -> str:
    """A duration for a message: ``12.345 ms``, ``1.500 s``, ``850 us``, ``40 ns``."""
    size = abs(nanos)
    if size >= _NANOS_PER_SECOND:
        return f"{nanos / _NANOS_PER_SECOND:.3f} s"
    if size >= 1_000_000:
        return f"{nanos / 1_000_000:.3f} ms"
    if size >= 1_000:
        return f"{nanos / 1_000:.1f} us"
    return f"{nanos} ns"



def constraint_location(constraint: Expr | Timing | None, transition: Transition) -> str:
    """Where a broken constraint is written (its time clause, its refinement), else where its
    interaction is: the live monitor, verify and generated code all locate a violation so."""
    location = getattr(constraint, "location", None)
    return str(location) if location is not None and location.line > 0 else str(transition.location)

class Rule:
    """What the monitor does on one transition beyond the plain step.

    Attributes:
        transition: the transition it belongs to.
        within: the deadline this side checks at the action, in ns: the sender's ``within``
            (None with ``else timeout``, which binds the receiver alone); on a receive, the
            receiver's deadline (enforced while it waits, only counted here).
        every, low, high: the period and the bounds ``every - jitter``, ``every + jitter`` of the
            gap between two sends of this interaction (sender only; None, 0, 0 without one).
        check: the refinement's compiled predicate (the reference, which says why not), or None.
        fast: the same refinement as one Python function: True when it holds (else: ask ``check``).
        stamps: the action's time becomes the role's previous action (the target state, or
            some state after it before another action, has a deadline).
        remembers: the payload's fields some refinement of the machine reads as an earlier payload.
        period: the clock of this interaction's period, shared by all its branches (a choice's
            period runs from its previous send, whichever label that was), or None.
        checked: how many times its constraints were checked.
        closest: the smallest margin seen, in ns to the nearest time bound (negative: missed),
            or None if it has no time bound or none was checked.
    """

    __slots__ = ("check", "checked", "closest", "every", "fast", "high", "low", "period", "remembers", "stamps",
                 "timed", "timeouts", "transition", "within")

    def __init__(self, transition: Transition, stamps: bool, remembers: tuple[str, ...],
                 period: PeriodClock | None = None) -> None:
        self.transition = transition
        timing = transition.timing or Timing()
        sending = transition.action == "send"
        self.within: int | None = timing.within if not (sending and timing.on_expiry) else None
        self.every: int | None = timing.every if sending else None
        self.low = (timing.every or 0) - timing.jitter
        self.high = (timing.every or 0) + timing.jitter
        refinement = transition.refinement
        self.check: Predicate | None = compile_predicate(refinement) if refinement is not None else None
        self.fast: FastCheck | None = (fast_predicate(refinement, _own_fields(transition))
                                       if refinement is not None else None)
        self.stamps = stamps
        self.remembers = remembers
        self.timed = self.within is not None or self.every is not None or stamps
        self.period = period if self.every is not None else None
        self.checked = 0
        self.closest: int | None = None
        self.timeouts = 0  # deadlines passed with ``else timeout`` taken

    def describe(self) -> str:
        """The transition with its constraints, as a statistics key: ``!Move(cmd) every 20ms +- 2ms``."""
        parts = [str(self.transition)]
        if self.transition.timing is not None and str(self.transition.timing):
            parts.append(str(self.transition.timing))
        if self.transition.refinement is not None:
            predicate = f"{{{print_expr(self.transition.refinement)}}}"
            if predicate not in parts[0]:  # a field's refinement is already in the record's print
                parts.append(predicate)
        return " ".join(parts)

    def margin(self, nanos: int) -> None:
        """Keep ``nanos`` if it is the closest to a bound seen yet."""
        if self.closest is None or nanos < self.closest:
            self.closest = nanos

    def statistics(self) -> ConstraintCheck:
        """What was seen so far, as a read-only record."""
        return ConstraintCheck(self.checked, self.closest, self.timeouts)


class PeriodClock:
    """When an interaction with a period was last sent (ns on the role's clock), shared by its branches."""

    __slots__ = ("last",)

    def __init__(self) -> None:
        self.last: int | None = None


class Plan:
    """The constraints of one machine, per state.

    Attributes:
        rules: per state, the rule of each transition that has one, keyed as the monitor's
            steps are: ``(action, peer, label)``.
        deadlines: per state, for each peer it may receive from under a deadline, the earliest
            ``(within ns, else timeout, transition)``; empty where nothing is timed.
        stamps_initial: the initial state has a deadline: the endpoint's start is the first
            previous action.
    """

    __slots__ = ("deadlines", "rules", "stamps_initial")

    def __init__(self, rules: list[dict[tuple[str, str | None, str], Rule]],
                 deadlines: list[dict[str | None, tuple[int, bool, Transition]]], stamps_initial: bool) -> None:
        self.rules = rules
        self.deadlines = deadlines
        self.stamps_initial = stamps_initial


def plan_for(machine: StateMachine) -> Plan:
    """The rules of ``machine``'s own states (its parallel branches have monitors of their own)."""
    timed_states = {state for state, row in enumerate(machine.table)
                    if any(_deadline_at(t) is not None for t in row.values())}
    earlier = _earlier_names(machine)
    rules: list[dict[tuple[str, str | None, str], Rule]] = []
    deadlines: list[dict[str | None, tuple[int, bool, Transition]]] = []
    for row in machine.table:
        own: dict[tuple[str, str | None, str], Rule] = {}
        due: dict[str | None, tuple[int, bool, Transition]] = {}
        period = PeriodClock()  # a state's sends are the branches of one interaction: one period
        for key, t in row.items():
            remembers = tuple(name for name in _own_fields(t) if name in earlier)
            stamps = t.target in timed_states
            if t.timing is not None or t.refinement is not None or stamps or remembers:
                own[key] = Rule(t, stamps, remembers, period)
            if t.action == "recv" and t.timing is not None and t.timing.within is not None:
                known = due.get(t.peer)
                if known is None or t.timing.within < known[0]:
                    due[t.peer] = (t.timing.within, t.timing.on_expiry, t)
        rules.append(own)
        deadlines.append(due)
    return Plan(rules, deadlines, machine.initial in timed_states)


def _deadline_at(t: Transition) -> int | None:
    """The deadline the owner of a state must know its previous action for, if ``t`` has one."""
    timing = t.timing
    if timing is None or timing.within is None:
        return None
    if t.action == "send" and timing.on_expiry:  # the receiver's alone
        return None
    return timing.within


def _own_fields(t: Transition) -> tuple[str, ...]:
    """The field names of ``t``'s record payload (none for other sorts)."""
    fields = t.sort.fields if t.sort is not None and t.sort.fields is not None else ()
    return tuple(f.name for f in fields)


def _earlier_names(machine: StateMachine) -> frozenset[str]:
    """The first names of the machine's refinements that are not fields of their own payload:
    those an earlier payload gives (the monitor keeps their latest values)."""
    names: set[str] = set()
    for row in machine.table:
        for t in row.values():
            if t.refinement is not None:
                heads: set[str] = set()
                _collect(t.refinement, heads)
                names |= heads - set(_own_fields(t))
    return frozenset(names)


def _collect(expr: Expr, names: set[str]) -> None:
    if isinstance(expr, Path):
        names.add(expr.parts[0])
    elif isinstance(expr, Unary):
        _collect(expr.operand, names)
    elif isinstance(expr, Binary):
        _collect(expr.left, names)
        _collect(expr.right, names)
    elif isinstance(expr, Compare):
        for operand in expr.operands:
            _collect(operand, names)
    elif isinstance(expr, Call):
        for arg in expr.args:
            _collect(arg, names)

