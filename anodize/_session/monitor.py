"""The run-time monitor: one role's (or one parallel branch's) state machine.

Every send is checked before anything leaves (the sender is to blame), every
receive when it arrives (the peer is to blame). A check is one dictionary
look-up in a table compiled once from the state machine, plus the payload
check of the transition.

A payload's type is looked up by identity (``id(type(payload))``), never hashed or compared:
a metaclass may redefine ``__eq__`` and ``__hash__`` to pass for ``int`` (see payloads.py for
the subclass policy, which the compiled core shares).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from sessiontypes import StateMachine, Transition

from ..errors import Action, DeadlineMissedError, ProtocolViolationError
from .payloads import Validator, exact_types_for, identities, real_name, validator_for
from .statistics import ConstraintCheck
from .timed import Rule, constraint_location, format_nanos, plan_for

__all__ = ["Monitor", "TIMEOUT"]

TIMEOUT = "timeout"
"""The label ``recv`` returns (with no payload) when a deadline with ``else timeout`` passes."""


# (target state, the first type accepted at once (None: none is), full payload check, the transition
# it came from, all the types accepted at once (the compiled core reads them; they also keep the
# identities that follow theirs), their identities). A payload of type `kind` fits at once when
# `kind is step[1] or id(kind) in step[5]`: one `is` for the common case, no hashing of `kind`.
# Then the transition's constraints (timed.Rule), or None: a step with a rule accepts no type at
# once (empty step[4], step[5]), so the Python fast paths hand it to Monitor.send / recv. The last
# item is what the compiled core needs to check such a step itself (CompiledRule), or None.
_Step = tuple[int, type | None, Validator, Transition, tuple[type, ...], frozenset[int], Rule | None,
              "CompiledRule | None"]

# A constrained step as the compiled core checks it (_endpoint_core.c): the exact payload types
# that pass at once, or for a record the (field name, exact types) of each field (then the payload
# must be a dict with exactly those fields); the refinement's fast check (None: none); the
# deadline in ns checked at the action (None: none); whether the action is time-stamped; the rule,
# whose counters it updates. Only for a rule without a period and without remembered fields; the
# compiled core reads the clock once, and hands anything it does not pass at once, with that
# reading, to Monitor.send / recv, which decide (and raise) as for every other step.
CompiledRule = tuple[tuple[type, ...], "tuple[tuple[str, tuple[type, ...]], ...] | None",
                     "Callable[[object, dict[str, object]], object] | None", "int | None", bool, "Rule | None"]


class Monitor:
    """Enforces one state machine; ``state`` is the current state.

    ``sends[state]`` / ``recvs[state]`` map ``(peer, label)`` to a step
    ``(target, first exact type, validator, transition, exact types, their identities)``; the
    endpoint's hot path reads them directly and calls :meth:`send` / :meth:`recv` only to raise.

    Time and value constraints (``sessiontypes.constraints``): a constrained step has a rule
    (:mod:`.timed`) and is always checked here. ``clock`` gives the role's clock in whole
    nanoseconds; it is read only at constrained actions and at actions after which a deadline
    runs (``previous`` is then the time of the role's previous action). ``deadlines[state]``
    maps each peer the state waits for under a deadline to ``(within ns, else timeout, transition)``;
    ``receives_from[state]`` is the peers the state may receive from; ``recv_peers[state]``,
    which the compiled core reads, the same but empty where a deadline runs: the compiled core
    blocks only in states without one and leaves the rest to the Python path, which waits no
    longer than the deadline.
    """

    __slots__ = ("clock", "deadlines", "earlier", "fork_states", "machine", "previous", "protocol", "receives_from",
                 "recv_peers", "recvs", "role", "rules", "sends", "state")

    def __init__(self, machine: StateMachine, protocol: str, role: str,
                 clock: Callable[[], int] | None = None) -> None:
        self.protocol = protocol
        self.role = role
        self.machine = machine
        self.state = machine.initial
        self.clock = clock or time.monotonic_ns  # the clock of time.monotonic(), in exact ns
        plan = plan_for(machine)
        self.rules: list[Rule] = [rule for row in plan.rules for rule in row.values()]
        self.deadlines = plan.deadlines
        self.earlier: dict[str, object] = {}  # the latest value of each field an earlier payload gave
        # The time of the role's previous action (ns), where a deadline needs it: the start first.
        self.previous: int | None = self.clock() if plan.stamps_initial else None
        validators: dict[int, tuple[Validator, tuple[type, ...], frozenset[int]]] = {}
        self.sends: list[dict[tuple[str | None, str], _Step]] = []
        self.recvs: list[dict[tuple[str | None, str], _Step]] = []
        for transitions in machine.table:
            sends: dict[tuple[str | None, str], _Step] = {}
            recvs: dict[tuple[str | None, str], _Step] = {}
            rules = plan.rules[len(self.sends)]
            for (action, peer, label), t in transitions.items():
                key = id(t.sort)
                if key not in validators:
                    # An int fits a float sort too, but floats are what it mostly carries: first.
                    exact = tuple(sorted(exact_types_for(t.sort), key=lambda kind: kind is int))
                    validators[key] = (validator_for(t.sort), exact, identities(exact))
                check, exact, ids = validators[key]
                rule = rules.get((action, peer, label))
                compiled = _compiled_rule(rule, exact, t) if rule is not None or not exact else None
                if rule is not None:  # no type is taken at once: the step is always checked here
                    exact, ids = (), frozenset()
                (sends if action == "send" else recvs)[(peer, label)] = (
                    t.target, exact[0] if exact else None, check, t, exact, ids, rule, compiled)
            self.sends.append(sends)
            self.recvs.append(recvs)
        # For each state, the peers it may receive from (checked before blocking).
        self.receives_from: list[frozenset[str | None]] = [frozenset(p for p, _ in r) for r in self.recvs]
        # What the compiled core reads (by this name) before it blocks with no timer: the same,
        # but empty where a deadline runs, so that such a receive takes the Python path.
        self.recv_peers: list[frozenset[str | None]] = [
            frozenset() if due else peers for peers, due in zip(self.receives_from, self.deadlines, strict=True)]
        self.fork_states = frozenset(machine.forks)

    def send(self, to: str | None, label: str, payload: object, now: int | None = None) -> None:
        """Step on sending; raises ProtocolViolationError blaming this role.

        ``now``: the clock's reading for a constrained step, where the caller (the compiled
        core) has taken it already; None: the monitor reads the clock if the step needs it."""
        step = self.sends[self.state].get((to, label))
        if step is None:
            raise self.violation(Action("send", to, label, _type_name(payload)), blame=self.role)
        if (kind := type(payload)) is not step[1] and id(kind) not in step[5]:
            reason = step[2](payload)
            if reason is not None:
                raise self.violation(Action("send", to, label, _type_name(payload)), self.role,
                                     reason, step[3])
        rule = step[6]
        if rule is None:
            self.state = step[0]
        else:
            self._constrained(rule, "send", to, label, payload, self.role, now)

    def recv(self, frm: str | None, label: str, payload: object, now: int | None = None) -> None:
        """Step on receiving; raises ProtocolViolationError blaming the sender (``now``: as for
        :meth:`send`)."""
        step = self.recvs[self.state].get((frm, label))
        if step is None:
            raise self.violation(Action("recv", frm, label, _type_name(payload)), blame=frm or "the peer")
        if (kind := type(payload)) is not step[1] and id(kind) not in step[5]:
            reason = step[2](payload)
            if reason is not None:
                raise self.violation(Action("recv", frm, label, _type_name(payload)), frm or "the peer",
                                     reason, step[3])
        rule = step[6]
        if rule is None:
            self.state = step[0]
        else:
            self._constrained(rule, "recv", frm, label, payload, frm or "the peer", now)

    def _constrained(self, rule: Rule, kind: str, peer: str | None, label: str, payload: object,
                     blame: str, now: int | None = None) -> None:
        """Check a step's constraints (raising, nothing changed, on a violation), then take it.

        A send is checked for its deadline, its period, then its refinement; a receive for its
        refinement (its deadline is the wait's, :meth:`expire`)."""
        rule.checked += 1
        if rule.timed:
            if now is None:  # else the compiled core read the clock for this action already
                now = self.clock()
            self._check_time(rule, kind, now, peer, label, payload, blame)
        else:
            now = 0
        fast = rule.fast
        if fast is not None:
            try:
                held = fast(payload, self.earlier) is True
            except Exception:  # the reference evaluates it again, and says why
                held = False
            if not held and rule.check is not None and (reason := rule.check(payload, self.earlier)) is not None:
                raise self.violation(Action(kind, peer, label, _type_name(payload)), blame,
                                     f"{reason} for {label} {_short(payload)}", rule.transition,
                                     constraint_location(rule.transition.refinement, rule.transition))
        if rule.remembers and type(payload) is dict:
            for name in rule.remembers:
                self.earlier[name] = payload[name]
        if rule.period is not None:
            rule.period.last = now
        if rule.stamps:
            self.previous = now
        self.state = rule.transition.target

    def _check_time(self, rule: Rule, kind: str, now: int, peer: str | None, label: str, payload: object,
                    blame: str) -> None:
        """A send's deadline and period at ``now`` (raising DeadlineMissedError); a receive's margin."""
        if kind != "send":
            if rule.within is not None and self.previous is not None:
                margin = rule.within - (now - self.previous)
                if margin >= 0:  # else a late reader took a message that was there in time: no margin to tell
                    rule.margin(margin)
            return
        if rule.within is not None:
            elapsed = now - (self.previous if self.previous is not None else now)
            if rule.closest is None or rule.within - elapsed < rule.closest:
                rule.closest = rule.within - elapsed
            if elapsed > rule.within:
                raise self._missed(Action("send", peer, label, _type_name(payload)), rule.transition, blame,
                                   f"deadline missed: sent {format_nanos(elapsed)} after {self.role}'s previous "
                                   f"action, later than within {format_nanos(rule.within)}",
                                   rule.within, elapsed - rule.within, "deadline")
        if rule.period is not None and rule.period.last is not None and rule.every is not None:
            gap = now - rule.period.last
            rule.margin(min(gap - rule.low, rule.high - gap))
            if not rule.low <= gap <= rule.high:
                early = gap < rule.low
                off = gap - rule.low if early else gap - rule.high
                raise self._missed(Action("send", peer, label, _type_name(payload)), rule.transition, blame,
                                   f"period missed: sent {format_nanos(gap)} after the interaction's previous send, "
                                   f"{format_nanos(abs(off))} too {'early' if early else 'late'} for "
                                   f"{rule.transition.timing}", rule.every, off, "period")

    def deadline(self, peer: str | None) -> tuple[int, bool, Transition] | None:
        """When the message awaited from ``peer`` (None: from any peer) is due, on the role's clock
        in ns, whether ``else timeout`` was written, and the interaction; None without a deadline."""
        due = self.deadlines[self.state]
        if not due or self.previous is None:
            return None
        if peer is not None:
            found = due.get(peer)
        else:
            found = min(due.values(), key=lambda entry: entry[0])
        if found is None:
            return None
        within, on_expiry, transition = found
        return self.previous + within, on_expiry, transition

    def expire(self, peer: str | None) -> bool:
        """The deadline of the message awaited from ``peer`` (None: any) has passed with nothing
        there. With ``else timeout``: the timeout becomes the previous action and True is
        returned (the state does not change); else DeadlineMissedError blames the sender."""
        found = self.deadline(peer)
        assert found is not None, "expire() without a deadline"
        due, on_expiry, transition = found
        now = self.clock()
        within = transition.timing.within if transition.timing is not None else None
        assert within is not None
        if on_expiry:
            self.previous = now
            for rule in self.rules:
                if rule.transition is transition:
                    rule.timeouts += 1  # the protocol's way on, not a miss: no margin
            return True
        sender = transition.peer or "the peer"
        raise self._missed(Action("recv", transition.peer, "*"), transition, sender,
                           f"deadline missed: nothing from {sender} within {format_nanos(within)} of "
                           f"{self.role}'s previous action", within, now - due, "deadline")

    def constraint_statistics(self) -> dict[str, ConstraintCheck]:
        """Per constrained interaction of this machine, how it fared so far."""
        found: dict[str, ConstraintCheck] = {}
        for rule in self.rules:
            if rule.transition.timing is None and rule.transition.refinement is None:
                continue
            key = rule.describe()
            check = rule.statistics()
            known = found.get(key)
            found[key] = check if known is None else known.joined(check)
        return found

    def _missed(self, actual: Action, transition: Transition, blame: str, reason: str, deadline: int, late: int,
                kind: str) -> DeadlineMissedError:
        plain = self.violation(actual, blame, reason, transition, constraint_location(transition.timing, transition))
        return DeadlineMissedError(plain.protocol, plain.role, plain.peer, plain.state, plain.expected, actual,
                                   blame, plain.location, reason, deadline, late, kind)

    @property
    def at_fork(self) -> bool:
        return self.state in self.fork_states

    @property
    def finished(self) -> bool:
        return self.machine.is_final(self.state)

    def expects_from(self, peer: str) -> bool:
        """Whether the current state can receive from ``peer``."""
        return peer in self.receives_from[self.state]

    def violation(self, actual: Action, blame: str, reason: str = "",
                  transition: Transition | None = None, where: str | None = None) -> ProtocolViolationError:
        """Describe ``actual`` against what the current state allows (``where``: the location of
        the constraint it broke, else the interaction's)."""
        allowed = self.machine.expected(self.state)
        expected = [Action(t.action, t.peer, t.label, t.sort.spelling if t.sort else None) for t in allowed]
        if transition is None and allowed:  # no interaction of its own: point at the first one allowed
            transition = allowed[0]
        location = where if where is not None else str(transition.location) if transition is not None else ""
        state = f"{self.state} ({self.machine.describe(self.state)})"
        return ProtocolViolationError(self.protocol, self.role, actual.peer, state, expected, actual,
                                      blame, location, reason)


def _compiled_rule(rule: Rule | None, exact: tuple[type, ...], transition: Transition) -> CompiledRule | None:
    """What the compiled core needs to check ``rule``'s step itself (None: a record's fields
    alone), or None if it leaves it here."""
    if rule is not None and (rule.period is not None or rule.remembers):
        return None
    fields: tuple[tuple[str, tuple[type, ...]], ...] | None = None
    sort = transition.sort
    if sort is not None and sort.fields is not None:
        listed = []
        for field in sort.fields:
            kinds = tuple(sorted(exact_types_for(field.sort), key=lambda kind: kind is int))
            if not kinds or field.sort is None:  # a field needing its full check (nat, a dataclass...)
                return None
            listed.append((field.name, kinds))
        fields = tuple(listed)
    elif not exact:
        return None
    if rule is None:
        return (exact, fields, None, None, False, None) if fields is not None else None
    return (exact, fields, rule.fast, rule.within, rule.stamps, rule)


def _short(payload: object) -> str:
    """A payload for a message: its repr, cut short."""
    text = repr(payload)
    return text if len(text) <= 120 else text[:117] + "..."


def _type_name(payload: object) -> str | None:
    return None if payload is None else real_name(type(payload))
