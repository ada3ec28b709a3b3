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

from sessiontypes import StateMachine, Transition

from ..errors import Action, ProtocolViolationError
from .payloads import Validator, exact_types_for, identities, real_name, validator_for

__all__ = ["Monitor"]

# (target state, identities of the types accepted at once, full payload check, the transition it
# came from, those types themselves: they keep the identities theirs, and the compiled core reads them)
_Step = tuple[int, frozenset[int], Validator, Transition, tuple[type, ...]]


class Monitor:
    """Enforces one state machine; ``state`` is the current state.

    ``sends[state]`` / ``recvs[state]`` map ``(peer, label)`` to a step
    ``(target, identities of the exact types, validator, transition, exact types)``; the
    endpoint's hot path reads them directly and calls :meth:`send` / :meth:`recv` only to raise.
    """

    __slots__ = ("fork_states", "machine", "protocol", "recv_peers", "recvs", "role", "sends", "state")

    def __init__(self, machine: StateMachine, protocol: str, role: str) -> None:
        self.protocol = protocol
        self.role = role
        self.machine = machine
        self.state = machine.initial
        validators: dict[int, tuple[frozenset[int], Validator, tuple[type, ...]]] = {}
        self.sends: list[dict[tuple[str | None, str], _Step]] = []
        self.recvs: list[dict[tuple[str | None, str], _Step]] = []
        for transitions in machine.table:
            sends: dict[tuple[str | None, str], _Step] = {}
            recvs: dict[tuple[str | None, str], _Step] = {}
            for (action, peer, label), t in transitions.items():
                key = id(t.sort)
                if key not in validators:
                    exact = tuple(exact_types_for(t.sort))
                    validators[key] = (identities(exact), validator_for(t.sort), exact)
                ids, check, exact = validators[key]
                (sends if action == "send" else recvs)[(peer, label)] = (t.target, ids, check, t, exact)
            self.sends.append(sends)
            self.recvs.append(recvs)
        # For each state, the peers it may receive from (checked before blocking).
        self.recv_peers: list[frozenset[str | None]] = [frozenset(p for p, _ in r) for r in self.recvs]
        self.fork_states = frozenset(machine.forks)

    def send(self, to: str | None, label: str, payload: object) -> None:
        """Step on sending; raises ProtocolViolationError blaming this role."""
        step = self.sends[self.state].get((to, label))
        if step is None:
            raise self.violation(Action("send", to, label, _type_name(payload)), blame=self.role)
        if id(type(payload)) not in step[1]:
            reason = step[2](payload)
            if reason is not None:
                raise self.violation(Action("send", to, label, _type_name(payload)), self.role,
                                     reason, step[3])
        self.state = step[0]

    def recv(self, frm: str | None, label: str, payload: object) -> None:
        """Step on receiving; raises ProtocolViolationError blaming the sender."""
        step = self.recvs[self.state].get((frm, label))
        if step is None:
            raise self.violation(Action("recv", frm, label, _type_name(payload)), blame=frm or "the peer")
        if id(type(payload)) not in step[1]:
            reason = step[2](payload)
            if reason is not None:
                raise self.violation(Action("recv", frm, label, _type_name(payload)), frm or "the peer",
                                     reason, step[3])
        self.state = step[0]

    @property
    def at_fork(self) -> bool:
        return self.state in self.fork_states

    @property
    def finished(self) -> bool:
        return self.machine.is_final(self.state)

    def expects_from(self, peer: str) -> bool:
        """Whether the current state can receive from ``peer``."""
        return peer in self.recv_peers[self.state]

    def violation(self, actual: Action, blame: str, reason: str = "",
                  transition: Transition | None = None) -> ProtocolViolationError:
        """Describe ``actual`` against what the current state allows."""
        allowed = self.machine.expected(self.state)
        expected = [Action(t.action, t.peer, t.label, t.sort.spelling if t.sort else None) for t in allowed]
        if transition is None and allowed:  # no interaction of its own: point at the first one allowed
            transition = allowed[0]
        location = str(transition.location) if transition is not None else ""
        state = f"{self.state} ({self.machine.describe(self.state)})"
        return ProtocolViolationError(self.protocol, self.role, actual.peer, state, expected, actual,
                                      blame, location, reason)


def _type_name(payload: object) -> str | None:
    return None if payload is None else real_name(type(payload))
