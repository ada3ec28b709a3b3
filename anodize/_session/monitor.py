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

# (target state, the first type accepted at once (None: none is), full payload check, the transition
# it came from, all the types accepted at once (the compiled core reads them; they also keep the
# identities that follow theirs), their identities). A payload of type `kind` fits at once when
# `kind is step[1] or id(kind) in step[5]`: one `is` for the common case, no hashing of `kind`.
_Step = tuple[int, type | None, Validator, Transition, tuple[type, ...], frozenset[int]]


class Monitor:
    """Enforces one state machine; ``state`` is the current state.

    ``sends[state]`` / ``recvs[state]`` map ``(peer, label)`` to a step
    ``(target, first exact type, validator, transition, exact types, their identities)``; the
    endpoint's hot path reads them directly and calls :meth:`send` / :meth:`recv` only to raise.
    """

    __slots__ = ("fork_states", "machine", "protocol", "recv_peers", "recvs", "role", "sends", "state")

    def __init__(self, machine: StateMachine, protocol: str, role: str) -> None:
        self.protocol = protocol
        self.role = role
        self.machine = machine
        self.state = machine.initial
        validators: dict[int, tuple[Validator, tuple[type, ...], frozenset[int]]] = {}
        self.sends: list[dict[tuple[str | None, str], _Step]] = []
        self.recvs: list[dict[tuple[str | None, str], _Step]] = []
        for transitions in machine.table:
            sends: dict[tuple[str | None, str], _Step] = {}
            recvs: dict[tuple[str | None, str], _Step] = {}
            for (action, peer, label), t in transitions.items():
                key = id(t.sort)
                if key not in validators:
                    # An int fits a float sort too, but floats are what it mostly carries: first.
                    exact = tuple(sorted(exact_types_for(t.sort), key=lambda kind: kind is int))
                    validators[key] = (validator_for(t.sort), exact, identities(exact))
                check, exact, ids = validators[key]
                (sends if action == "send" else recvs)[(peer, label)] = (
                    t.target, exact[0] if exact else None, check, t, exact, ids)
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
        if (kind := type(payload)) is not step[1] and id(kind) not in step[5]:
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
        if (kind := type(payload)) is not step[1] and id(kind) not in step[5]:
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
