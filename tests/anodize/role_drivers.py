"""Role implementations for runtime tests: drivers that walk a role's state machine.

A :class:`RoleDriver` is a role function (``driver(ep)``) that follows the
role's projection: at a state with sends it picks one allowed send (seeded,
so two runs make the same choices), at a state with receives it calls
``ep.recv(peer)`` for the one peer the state receives from (``ep.recv_any`` when it
may receive from several: a choice learnt from whichever peer tells first), at a fork it
calls ``ep.fork()`` and runs each branch on its own thread, and it returns
at a final state. After ``exit_after`` actions the chooser prefers the send
that leads soonest to ``end``, which bounds loops that have an exit.

Every driver of one run shares a :class:`Recorder`, which keeps the
``(label, payload)`` sequence of every channel as sent and as received.

A driver can also *deviate*: at its ``deviate_at``-th action (or earlier, at a
fork or at the end) it attempts a send its local type does not allow.
"""

from __future__ import annotations

import math
import random
import threading
import time
from dataclasses import dataclass, field
from queue import SimpleQueue

import sessiontypes
from anodize import AnodizeError, Endpoint, System
from sessiontypes import GlobalType, Sort, StateMachine, Transition

__all__ = ["EXIT_AFTER", "BOGUS_LABEL", "Recorder", "RoleDriver", "Attempt", "distances",
           "can_always_end", "has_fork", "payload_for", "machines_of", "load_global",
           "build_system"]

EXIT_AFTER = 12          # actions (per thread) after which the chooser heads for the exit
BOGUS_LABEL = "deviant"  # a label no generated protocol uses

Channel = tuple[str, str]


def load_global(text: str, name: str = "G") -> GlobalType:
    return sessiontypes.loads(text, "generated.proto").globals[name]


def machines_of(global_type: GlobalType) -> dict[str, StateMachine]:
    return {role: global_type.project(role).fsm() for role in global_type.roles}


# ---- analysis of a machine ---------------------------------------------------------------

def distances(machine: StateMachine) -> list[float]:
    """For each state, the fewest actions to ``end`` (``inf`` where there is no way out).

    A fork costs one more than its slowest branch needs from its start.
    """
    fork_cost = {state: 1 + max(distances(branch)[branch.initial] for branch in branches)
                 for state, branches in machine.forks.items()}
    dist = [0.0 if machine.is_final(s) else fork_cost.get(s, math.inf) for s in machine.states]
    changed = True
    while changed:  # Bellman-Ford on a small graph
        changed = False
        for state in machine.states:
            for t in machine.table[state].values():
                if dist[t.target] + 1 < dist[state]:
                    dist[state] = dist[t.target] + 1
                    changed = True
    return dist


def _reachable(machine: StateMachine) -> set[int]:
    seen = {machine.initial}
    stack = [machine.initial]
    while stack:
        for t in machine.table[stack.pop()].values():
            if t.target not in seen:
                seen.add(t.target)
                stack.append(t.target)
    return seen


def can_always_end(machine: StateMachine) -> bool:
    """From every reachable state (in forks too) some path leads to ``end``."""
    dist = distances(machine)
    reachable = _reachable(machine)
    return (all(dist[s] < math.inf for s in reachable)
            and all(can_always_end(b) for s in reachable for b in machine.forks.get(s, ())))


def has_fork(machine: StateMachine) -> bool:
    return bool(machine.forks)


# ---- payloads ------------------------------------------------------------------------------

def payload_for(sort: Sort | None, rng: random.Random) -> object:
    """A value of ``sort`` (builtin sorts and records of them), None when the label carries nothing."""
    if sort is None:
        return None
    if sort.fields is not None:
        return {f.name: payload_for(f.sort, rng) for f in sort.fields}
    match sort.key:
        case "int":
            return rng.randint(-1000, 1000)
        case "nat":
            return rng.randint(0, 1000)
        case "bool":
            return rng.random() < 0.5
        case "str":
            return rng.choice(["", "x", "héllo", "a b"])
        case "float":
            return rng.choice([0.5, -2.25, 1e9])
        case "bytes":
            return bytes(rng.randrange(256) for _ in range(rng.randrange(4)))
    raise AssertionError(f"no generator for sort {sort.key}")


# ---- recording ----------------------------------------------------------------------------

@dataclass
class Recorder:
    """Per channel, what was sent and what was received, in order.

    Each list is appended to by one thread only (a channel has one sending and
    one receiving branch), so no lock is needed.
    """

    roles: tuple[str, ...]
    sent: dict[Channel, list[tuple[str, object]]] = field(init=False)
    received: dict[Channel, list[tuple[str, object]]] = field(init=False)

    def __post_init__(self) -> None:
        pairs = [(a, b) for a in self.roles for b in self.roles if a != b]
        self.sent = {pair: [] for pair in pairs}
        self.received = {pair: [] for pair in pairs}

    def nonempty(self, which: dict[Channel, list[tuple[str, object]]]) -> dict[Channel, list[tuple[str, object]]]:
        return {pair: items for pair, items in which.items() if items}


@dataclass(frozen=True)
class Attempt:
    """The forbidden send a deviating driver attempted, and what it raised."""

    peer: str
    label: str
    payload: object
    state: int
    error: BaseException | None


# ---- the driver ---------------------------------------------------------------------------

class RoleDriver:
    """A role function that follows ``machine`` (see the module docstring).

    Args:
        role: the role it plays.
        machine: the role's state machine (its own copy; the endpoint has another).
        recorder: shared by every driver of the run.
        seed: makes every choice reproducible (branches get derived seeds).
        monitored: whether the run has monitors (see ``_fork``).
        deviate_at: attempt a forbidden send at this action of the main thread.
    """

    def __init__(self, role: str, machine: StateMachine, recorder: Recorder, seed: int,
                 monitored: bool = True, exit_after: int = EXIT_AFTER,
                 deviate_at: int | None = None) -> None:
        self.role = role
        self.machine = machine
        self.recorder = recorder
        self.seed = seed
        self.monitored = monitored
        self.exit_after = exit_after
        self.deviate_at = deviate_at
        self.pause = 0.0  # seconds to sleep before each send (for runs that end by timeout)
        self.attempt: Attempt | None = None
        self.used_unmonitored_fork_workaround = False

    def __call__(self, ep: Endpoint) -> None:
        self._walk(ep, self.machine, "", main=True)

    def _rng(self, path: str) -> random.Random:
        return random.Random(f"{self.seed}/{self.role}/{path}")

    def _walk(self, ep: Endpoint, machine: StateMachine, path: str, main: bool) -> None:
        rng = self._rng(path)
        dist = distances(machine)
        state = machine.initial
        steps = 0
        while True:
            at_fork = state in machine.forks
            final = machine.is_final(state)
            if main and self.deviate_at is not None and (steps >= self.deviate_at or at_fork or final):
                self._deviate(ep, machine, state, rng)
            if at_fork:
                self._fork(ep, machine.forks[state], path)
                return
            if final:
                return
            transitions = machine.expected(state)
            sends = [t for t in transitions if t.action == "send"]
            if sends:
                assert len(sends) == len(transitions), f"state {state} both sends and receives"
                t = self._choose(sends, dist, steps, rng)
                payload = self.payload(t, rng)
                assert t.peer is not None
                if self.pause:
                    time.sleep(self.pause)
                ep.send(t.peer, t.label, payload)
                self.recorder.sent[(self.role, t.peer)].append((t.label, payload))
            else:
                peers = sorted({str(t.peer) for t in transitions})
                if len(peers) == 1:
                    peer = peers[0]
                    message = ep.recv(peer)
                else:  # the first message to come decides (unmonitored: only from these peers)
                    peer, message = ep.recv_any(peers=peers)
                self.recorder.received[(peer, self.role)].append((message.label, message.payload))
                found = machine.step(state, "recv", peer, message.label)
                assert found is not None, f"{self.role} received {message} from {peer} in state {state}"
                t = found
            state = t.target
            steps += 1

    def payload(self, t: Transition, rng: random.Random) -> object:
        """The payload of send ``t`` (a subclass may pick values that keep or break its refinement)."""
        return payload_for(t.sort, rng)

    def _choose(self, sends: list[Transition], dist: list[float], steps: int,
                rng: random.Random) -> Transition:
        if steps >= self.exit_after:
            best = min(dist[t.target] for t in sends)
            sends = [t for t in sends if dist[t.target] == best]
        return rng.choice(sends)

    def _fork(self, ep: Endpoint, machines: tuple[StateMachine, ...], path: str) -> None:
        try:
            endpoints = ep.fork()
        except AnodizeError:
            if self.monitored:
                raise
            # Unmonitored endpoints refuse fork() (see test_fork_works_without_monitors);
            # their channels need no routing, so the branches can share the endpoint.
            self.used_unmonitored_fork_workaround = True
            endpoints = (ep,) * len(machines)
        assert len(endpoints) == len(machines)
        results: SimpleQueue[BaseException | None] = SimpleQueue()

        def branch(index: int) -> None:
            try:
                self._walk(endpoints[index], machines[index], f"{path}{index}.", main=False)
            except BaseException as error:  # handed to the role's thread, never lost
                results.put(error)
            else:
                results.put(None)

        for index in range(len(machines)):
            threading.Thread(target=branch, args=(index,), daemon=True,
                             name=f"driver:{self.role}/{path}{index}").start()
        for _ in machines:
            error = results.get()
            if error is not None:
                raise error  # fail fast: the role fails, so its peers are told at once

    def _deviate(self, ep: Endpoint, machine: StateMachine, state: int, rng: random.Random) -> None:
        """Attempt one send the state does not allow; must raise."""
        others = [r for r in self.recorder.roles if r != self.role]
        sends = [t for t in machine.expected(state) if t.action == "send"]
        payload: object = None
        if sends and rng.random() < 0.5 and len(others) > 1:
            # an allowed message to the wrong peer
            t = rng.choice(sends)
            peer = rng.choice([r for r in others if r != t.peer])
            label, payload = t.label, payload_for(t.sort, rng)
        elif sends:
            # the right peer, a label it does not allow
            peer, label = sends[0].peer or "", BOGUS_LABEL
        elif state in machine.forks or machine.is_final(state):
            peer, label = rng.choice(others), BOGUS_LABEL
        else:
            # a receiving state allows no send at all, even of a protocol label
            label = rng.choice(sorted({t.label for s in machine.states
                                       for t in machine.table[s].values()}))
            peer = rng.choice(others)
        try:
            ep.send(peer, label, payload)
        except BaseException as error:  # the test checks it is a ProtocolViolationError
            self.attempt = Attempt(peer, label, payload, state, error)
            raise
        self.attempt = Attempt(peer, label, payload, state, None)
        raise AssertionError(f"{self.role} sent {label} to {peer} in state {state} without a violation")


def build_system(global_type: GlobalType, seed: int, monitored: bool = True,
                 deviator: tuple[str, int] | None = None,
                 exit_after: int = EXIT_AFTER) -> tuple[System, Recorder, dict[str, RoleDriver]]:
    """A system with one driver per role (each role in its own group).

    Args:
        deviator: ``(role, action index)``: that role deviates at that action.
    """
    recorder = Recorder(global_type.roles)
    system = System(global_type, monitors=monitored)
    drivers = {}
    for role, machine in machines_of(global_type).items():
        deviate_at = deviator[1] if deviator is not None and deviator[0] == role else None
        drivers[role] = RoleDriver(role, machine, recorder, seed, monitored, exit_after, deviate_at)
        system.group(f"g_{role}").role(role, drivers[role])
    return system, recorder, drivers
