"""The time and value constraints of a protocol, judged on a recording (``anodize verify``).

A recording has one time per message, its log time: in an anodize recording the send time on
the sender's clock (on a channel from an external role, the time the receiving role took the
message), in another tool's recording the time the recorder got it. It stands for the
moment of the interaction on both roles' clocks: the transport's delay is not in the
recording. With that, the live monitor's rules (docs/language.md, "Time and value
constraints") read offline as:

* a role's *previous action* is its latest message, sent or received, on any recorded
  channel, in log-time order (a parallel branch: its own and its nested branches'; the
  role's own: any of its branches'); before its first there is none in the recording (when
  the endpoint was made is not recorded), so its first action's deadline is not judged;
* ``within D`` (without ``else timeout``): the message's log time minus the sender's
  previous action's is at most D (the sender's deadline), and minus the receiver's previous
  action's at most D (the receiver's); either missed blames the sender. With ``else
  timeout`` nothing is judged: the receiver may have taken timeouts the recording does not
  show, and nobody is blamed for those;
* ``every T +- J``: from the second message of the interaction on, the time since the
  previous one of the same interaction is in [T - J, T + J]; judged where the log times are
  the sender's (not on a channel from an external role, whose log times are when the
  receiver took each message: the receiver's pace, not the sender's);
* a refinement: evaluated on the decoded payload, with the names of earlier record payloads
  bound to the latest values the sender sent or received, in log-time order across its
  channels.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from sessiontypes import StateMachine, Transition
from sessiontypes.constraints import Expr, format_duration
from sessiontypes.refine import Predicate, compile_predicate, print_expr

from .._session.timed import constraint_location, format_nanos

__all__ = ["Breach", "RoleTimes", "Earlier", "judge_refinement", "judge_deadline", "judge_period",
           "constrained", "machines_of", "Held", "constraints_of"]

_SHOWN = 120  # characters of a payload a reason quotes (as the live monitor's)


@dataclass(frozen=True)
class Breach:
    """Why a message breaks a constraint.

    Attributes:
        kind: ``"deadline"``, ``"period"`` or ``"refinement"``.
        reason: the sentence the report prints.
        location: the ``.proto`` location of the constraint (else of its interaction).
        late: for a time constraint, how far outside it the message was, in ns (0 otherwise).
    """

    kind: str
    reason: str
    location: str
    late: int = 0


@dataclass
class Held:
    """One constraint of one label of a channel, and how it held on the messages judged
    (those before the channel's first violation, if it has one).

    Attributes:
        channel: ``"Sender->Receiver"``.
        label: the interaction's label.
        constraint: its canonical print: ``within 100ms``, ``every 20ms +- 2ms``, ``{abs(v) <= 1.5}``.
        judged: on how many messages it was judged.
        least: for a period, the shortest time between two messages, in ns (None: none judged).
        most: for a deadline, the longest time since the previous action; for a period, the
            longest between two messages; in ns (None: none judged).
    """

    channel: str
    label: str
    constraint: str
    judged: int = 0
    least: int | None = None
    most: int | None = None

    def measured(self, span: int) -> None:
        self.least = span if self.least is None else min(self.least, span)
        self.most = span if self.most is None else max(self.most, span)

    def __str__(self) -> str:
        head = f"{self.channel} {self.label} {self.constraint}"
        if self.constraint.endswith("else timeout"):
            return f"{head}: not judged (a late message was a timeout the recording does not show: nobody's fault)"
        if not self.judged:
            return f"{head}: judged on no message"
        held = f"{head}: held on {self.judged} message(s)"
        if self.constraint.startswith("within") and self.most is not None:
            return f"{held}, at most {format_nanos(self.most)} after the previous action"
        if self.constraint.startswith("every") and self.least is not None and self.most is not None:
            return f"{held}, {format_nanos(self.least)} to {format_nanos(self.most)} apart"
        return held


def constraints_of(machines: Mapping[str, StateMachine]) -> dict[tuple[str, str, str], Held]:
    """Every constraint of the senders' transitions, keyed by (channel, label, constraint):
    ``every``, ``within`` (with ``else timeout``: listed, never judged), refinements."""
    found: dict[tuple[str, str, str], Held] = {}
    for role, machine in sorted(machines.items()):
        for t in machine.all_transitions():
            if t.action != "send" or t.peer is None:
                continue
            channel = f"{role}->{t.peer}"
            for text in constraint_texts(t):
                found.setdefault((channel, t.label, text), Held(channel, t.label, text))
    return dict(sorted(found.items()))


def constraint_texts(t: Transition) -> list[str]:
    """The prints of ``t``'s constraints: period, deadline, refinement."""
    texts: list[str] = []
    timing = t.timing
    if timing is not None and timing.every is not None:
        texts.append(f"every {format_duration(timing.every)}"
                     + (f" +- {format_duration(timing.jitter)}" if timing.jitter else ""))
    if timing is not None and timing.within is not None:
        texts.append(f"within {format_duration(timing.within)}" + (" else timeout" if timing.on_expiry else ""))
    if t.refinement is not None:
        texts.append("{" + print_expr(t.refinement) + "}")
    return texts


def constrained(machines: Mapping[str, StateMachine]) -> tuple[bool, bool]:
    """Whether any transition of ``machines`` has a timing, and whether any has a refinement."""
    transitions = [t for m in machines.values() for t in m.all_transitions()]
    return (any(t.timing is not None for t in transitions), any(t.refinement is not None for t in transitions))


def machines_of(machine: StateMachine) -> Iterator[StateMachine]:
    """The machine and its parallel branches', depth first, in the order :class:`.channel_view.ChannelView`
    numbers them."""
    yield machine
    for branches in machine.forks.values():
        for branch in branches:
            yield from machines_of(branch)


class RoleTimes:
    """Each role's previous action: per machine (the role's, or a parallel branch), the log
    time of its latest message."""

    def __init__(self, machines: Mapping[str, StateMachine]) -> None:
        self._last: dict[str, list[int | None]] = {}
        self._within: dict[str, list[range]] = {}  # role -> per machine number: its own and its branches' numbers
        for role, machine in machines.items():
            sizes = [sum(1 for _ in machines_of(m)) for m in machines_of(machine)]
            self._within[role] = [range(number, number + size) for number, size in enumerate(sizes)]
            self._last[role] = [None] * len(sizes)

    def previous(self, role: str, machine: int) -> int | None:
        """The log time of ``role``'s previous action as ``machine`` sees it (None: none recorded)."""
        last = self._last[role]
        times = [t for t in (last[n] for n in self._within[role][machine]) if t is not None]
        return max(times) if times else None

    def act(self, role: str, machine: int | None, log_time: int) -> None:
        """``role`` acted at ``log_time`` in ``machine`` (None: in a machine not known, which then
        counts for every one of them: a deadline is rather not judged than judged from too early)."""
        last = self._last.get(role)
        if last is None:
            return
        for number in range(len(last)) if machine is None else (machine,):
            last[number] = log_time


class Earlier:
    """Per role, the latest value of each field of the record payloads it sent or received."""

    def __init__(self) -> None:
        self._fields: dict[str, dict[str, object]] = {}

    def of(self, role: str) -> Mapping[str, object]:
        return self._fields.get(role, {})

    def saw(self, role: str, payload: object) -> None:
        if isinstance(payload, dict):
            self._fields.setdefault(role, {}).update((k, v) for k, v in payload.items() if isinstance(k, str))


_PREDICATES: dict[Expr, Predicate] = {}


def judge_refinement(t: Transition, label: str, payload: object, earlier: Mapping[str, object]) -> Breach | None:
    """The refinement of ``t`` on ``payload`` (None: it holds, or there is none)."""
    if t.refinement is None:
        return None
    predicate = _PREDICATES.get(t.refinement)
    if predicate is None:
        predicate = _PREDICATES[t.refinement] = compile_predicate(t.refinement)
    reason = predicate(payload, earlier)
    if reason is None:
        return None
    shown = repr(payload)
    shown = shown if len(shown) <= _SHOWN else shown[:_SHOWN - 3] + "..."
    return Breach("refinement", f"{reason} for {label} {shown}", constraint_location(t.refinement, t))


def judge_deadline(t: Transition, role: str, sender: bool, previous: int | None, log_time: int) -> Breach | None:
    """``t``'s ``within`` for ``role`` (the sender, or the receiver) at ``log_time``."""
    timing = t.timing
    if timing is None or timing.within is None or timing.on_expiry or previous is None:
        return None
    gap = log_time - previous
    if gap <= timing.within:
        return None
    late = gap - timing.within
    what = "sent" if sender else f"it reached {role}"
    return Breach("deadline", f"deadline missed: {what} {format_nanos(gap)} after {role}'s previous action, later than "
                  f"within {format_nanos(timing.within)}", constraint_location(timing, t), late)


def judge_period(t: Transition, previous: int | None, log_time: int) -> Breach | None:
    """``t``'s ``every T +- J`` for a message at ``log_time``, the previous of its interaction at ``previous``."""
    timing = t.timing
    if timing is None or timing.every is None or previous is None:
        return None
    gap = log_time - previous
    low, high = timing.every - timing.jitter, timing.every + timing.jitter
    if low <= gap <= high:
        return None
    off, side = (low - gap, "early") if gap < low else (gap - high, "late")
    return Breach("period", f"period missed: sent {format_nanos(gap)} after the interaction's previous send, "
                  f"{format_nanos(off)} too {side} for {timing}", constraint_location(timing, t), off)

