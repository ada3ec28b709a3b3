"""Monitors that enforce time and value constraints (issue 29, item 3; timed-spec.md, "Meaning").

Each rule accepted and refused, with the exact message and the right blame, on both cores of
the endpoint (the compiled one and the Python reference): a late send, a period early and late,
a refinement on send and on arrival, a name from an earlier payload; a receiver's deadline that
passes while it waits (raised at the deadline, blaming the sender), a late reader that takes a
message already there, ``else timeout``; then a reference semantics written here against the
monitor on random timed traces, and whole runs on each transport.

Time is a fake clock the tests move (``network.clocks``), except where a receiver really waits:
there the only bound asserted is a generous one on the test's own wait.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path as FilePath
from typing import Any

import pytest
import timed_roles
from budget import examples
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from timed_machines import timed_global

import anodize
import sessiontypes
from anodize import TIMEOUT, DeadlineMissedError, ProtocolViolationError
from anodize._session.endpoint import Endpoint
from anodize._session.monitor import Monitor
from anodize._session.timed import to_nanos
from anodize._transport.inproc import InprocNetwork
from anodize.errors import error_from_data, error_to_data
from sessiontypes.constraints import Binary, Call, Compare, Expr, Number, Path, Text, Timing, Truth, Unary

MS = 1_000_000


class PythonEndpoint(Endpoint):
    """An endpoint on the Python core, whatever its base class."""

    send = Endpoint._send_python
    recv = Endpoint._recv_python


CORES = [pytest.param(Endpoint, id="compiled-or-python"), pytest.param(PythonEndpoint, id="python")]


class FakeClock:
    """A role's clock the test sets (seconds, as Endpoint.now() gives them)."""

    def __init__(self) -> None:
        self.t = 100.0
        self.readings = 0

    def now(self, branch: str) -> float:
        self.readings += 1
        return self.t

    def wall(self, branch: str) -> float:
        return self.t

    def advance(self, nanos: int) -> None:
        self.t += nanos / 1e9


def at(v: str) -> Path:
    return Path(tuple(v.split(".")))


def cmp(op: str, left: Expr, right: Expr) -> Compare:
    return Compare((op,), (left, right))


def setup(core: type[Endpoint], text: str, constraints: dict[tuple[str, str], tuple[Timing | None, Expr | None]],
          role: str, clock: FakeClock | None = None, roles: list[str] | None = None,
          ) -> tuple[Endpoint, InprocNetwork]:
    gt = timed_global(text, constraints, roles=roles)
    machines = {r: gt.project(r).fsm() for r in gt.roles}
    network = InprocNetwork([(a, b) for a in gt.roles for b in gt.roles if a != b],
                            doorbell_roles=[r for r, m in machines.items() if m.forks or m.waits_on_several()])
    if clock is not None:
        network.clocks = {role: clock}  # type: ignore[attr-defined]
    return core(role, "G", machines[role], network), network


def raised(call: Callable[..., object], *args: object) -> ProtocolViolationError:
    with pytest.raises(ProtocolViolationError) as info:
        call(*args)
    return info.value


STREAM = "global G(A, B) = mu t. A -> B : { num(x: int). t, fin. end }"


# ---- the sender: within, every +- jitter, refinements ---------------------------------------

@pytest.mark.parametrize("core", CORES)
def test_a_send_within_its_deadline_leaves_and_a_late_one_is_refused_blaming_the_sender(core: type[Endpoint]) -> None:
    clock = FakeClock()
    sender, network = setup(core, STREAM, {("A", "num"): (Timing(within=10 * MS), None)}, "A", clock)
    clock.advance(10 * MS)  # exactly the deadline after the endpoint was made: in time
    sender.send("B", "num", {"x": 1})
    clock.advance(10 * MS + 1)
    error = raised(sender.send, "B", "num", {"x": 2})
    assert isinstance(error, DeadlineMissedError)
    assert (error.blame, error.kind, error.deadline_ns, error.late_ns) == ("A", "deadline", 10 * MS, 1)
    assert str(error) == (
        "protocol G, role A: protocol violation by A: deadline missed: sent 10.000 ms after A's previous action, "
        "later than within 10.000 ms; in state 0 (+B{num(x: int).t, fin}) expected !B(fin), !B(num(x: int)), "
        "got !B(num(dict)) (timed.proto:1:24)")
    assert network.queues[("A", "B")].qsize() == 1  # the late one did not leave
    clock.advance(-5 * MS)  # the clock read again: in time once more (the refused send changed nothing)
    sender.send("B", "fin")


@pytest.mark.parametrize("core", CORES)
def test_a_period_sent_early_or_late_is_refused_and_one_within_the_jitter_leaves(core: type[Endpoint]) -> None:
    clock = FakeClock()
    sender, network = setup(core, STREAM, {("A", "num"): (Timing(every=20 * MS, jitter=2 * MS), None)}, "A", clock)
    sender.send("B", "num", {"x": 0})  # the first send has no period to keep
    clock.advance(18 * MS - 1)
    early = raised(sender.send, "B", "num", {"x": 1})
    assert isinstance(early, DeadlineMissedError)
    assert (early.blame, early.kind, early.deadline_ns, early.late_ns) == ("A", "period", 20 * MS, -1)
    assert ("period missed: sent 18.000 ms after the interaction's previous send, 1 ns too early for every 20ms +- 2ms"
            in str(early))
    clock.advance(1)
    sender.send("B", "num", {"x": 1})  # 18 ms: the earliest allowed
    clock.advance(22 * MS + 1000)
    late = raised(sender.send, "B", "num", {"x": 2})
    assert isinstance(late, DeadlineMissedError)
    assert (late.kind, late.late_ns) == ("period", 1000)
    assert "1.0 us too late for every 20ms +- 2ms" in str(late)
    clock.advance(-1000)
    sender.send("B", "num", {"x": 2})
    assert network.queues[("A", "B")].qsize() == 3


@pytest.mark.parametrize("core", CORES)
def test_a_refinement_false_on_send_is_refused_and_nothing_leaves(core: type[Endpoint]) -> None:
    sender, network = setup(core, STREAM, {("A", "num"): (None, cmp(">", at("x"), Number(0)))}, "A")
    sender.send("B", "num", {"x": 1})
    error = raised(sender.send, "B", "num", {"x": 0})
    assert not isinstance(error, DeadlineMissedError)
    assert (error.blame, error.reason) == ("A", "refinement {x > 0} is false for num {'x': 0}")
    assert error.location == "timed.proto:1:24"
    error = raised(sender.send, "B", "num", {"x": "one"})  # the sort refuses it first
    assert error.reason == "field x: expected a payload of sort int, got str"
    assert network.queues[("A", "B")].qsize() == 1


@pytest.mark.parametrize("core", CORES)
def test_a_refinement_that_cannot_be_evaluated_counts_as_false_with_its_reason(core: type[Endpoint]) -> None:
    bound = cmp("<=", Call("abs", (at("x"),)), Binary("/", Number(10), at("x")))
    sender, _ = setup(core, STREAM, {("A", "num"): (None, bound)}, "A")
    sender.send("B", "num", {"x": 2})
    error = raised(sender.send, "B", "num", {"x": 0})
    assert error.reason == "refinement {abs(x) <= 10 / x} cannot be evaluated: / divides by zero for num {'x': 0}"


@pytest.mark.parametrize("core", CORES)
def test_a_refinement_false_on_arrival_blames_the_sender(core: type[Endpoint]) -> None:
    refine = {("A", "num"): (None, cmp(">", at("x"), Number(0)))}
    receiver, network = setup(core, STREAM, refine, "B", roles=["B"])
    network.queues[("A", "B")].put(("num", {"x": 5}))
    network.queues[("A", "B")].put(("num", {"x": -5}))
    assert receiver.recv("A") == ("num", {"x": 5})
    error = raised(receiver.recv, "A")
    assert (error.role, error.blame, error.reason) == ("B", "A", "refinement {x > 0} is false for num {'x': -5}")


REQUEST = "global G(A, B) = mu t. A -> B : req(seq: int). B -> A : { ack(n: int). t, done. end }"


@pytest.mark.parametrize("core", CORES)
def test_a_name_from_an_earlier_payload_is_its_latest_value_on_both_sides(core: type[Endpoint]) -> None:
    echo = {("B", "ack"): (None, cmp("==", at("n"), at("seq")))}
    a, network = setup(core, REQUEST, echo, "A")
    b, _ = setup(core, REQUEST, echo, "B")
    b._in["A"] = network.queues[("A", "B")]
    b._out["A"] = (network.queues[("B", "A")], None)
    a.send("B", "req", {"seq": 7})
    assert b.recv("A") == ("req", {"seq": 7})
    error = raised(b.send, "A", "ack", {"n": 6})  # the sender checks it...
    assert (error.blame, error.reason) == ("B", "refinement {n == seq} is false for ack {'n': 6}")
    b.send("A", "ack", {"n": 7})
    assert a.recv("B") == ("ack", {"n": 7})
    a.send("B", "req", {"seq": 8})
    network.queues[("B", "A")].put(("ack", {"n": 7}))  # ...and so does the receiver (an older seq)
    error = raised(a.recv, "B")
    assert (error.role, error.blame) == ("A", "B")


# ---- the receiver: deadlines that pass while it waits, else timeout -------------------------

PING = "global G(A, B) = mu t. A -> B : { ping. t, fin. end }"


@pytest.mark.parametrize("core", CORES)
def test_a_receiver_waiting_past_its_deadline_gets_the_error_then_blaming_the_sender(core: type[Endpoint]) -> None:
    receiver, _ = setup(core, PING, {("A", "ping"): (Timing(within=50 * MS), None)}, "B")
    outcome: queue.Queue[BaseException | object] = queue.Queue()

    def wait() -> None:
        try:
            outcome.put(receiver.recv("A"))
        except BaseException as error:  # handed to the test
            outcome.put(error)

    threading.Thread(target=wait, daemon=True).start()
    error = outcome.get(timeout=30)  # nothing is ever sent: only the deadline ends the wait
    assert isinstance(error, DeadlineMissedError), error
    assert (error.role, error.blame, error.kind, error.deadline_ns) == ("B", "A", "deadline", 50 * MS)
    assert error.late_ns >= 0
    assert str(error).startswith("protocol G, role B: protocol violation by A: deadline missed: nothing from A "
                                 "within 50.000 ms of B's previous action; in state 0")


@pytest.mark.parametrize("core", CORES)
def test_a_late_reader_takes_a_message_that_is_there_and_a_missing_one_fails_at_once(core: type[Endpoint]) -> None:
    clock = FakeClock()
    receiver, network = setup(core, PING, {("A", "ping"): (Timing(within=10 * MS), None)}, "B", clock)
    network.queues[("A", "B")].put(("ping", None))
    clock.advance(50 * MS)  # B comes late: the message is there, B was late, not A
    assert receiver.recv("A") == ("ping", None)
    clock.advance(11 * MS)
    error = raised(receiver.recv, "A", 30)  # nothing there, deadline past: at once, not after 30 s
    assert isinstance(error, DeadlineMissedError)
    assert (error.blame, error.late_ns) == ("A", 1 * MS)


@pytest.mark.parametrize("core", CORES)
def test_else_timeout_returns_the_timeout_keeps_the_state_and_restarts_the_deadline(core: type[Endpoint]) -> None:
    clock = FakeClock()
    receiver, network = setup(core, PING, {("A", "ping"): (Timing(within=10 * MS, on_expiry=True), None)}, "B", clock)
    clock.advance(10 * MS)
    state = receiver.state
    assert receiver.recv("A", 30) == (TIMEOUT, None)
    assert receiver.state == state
    assert receiver.recv("A", 30) == (TIMEOUT, None)  # measured from the timeout: still due (0 left), still none
    clock.advance(3 * MS)
    network.queues[("A", "B")].put(("fin", None))
    assert receiver.recv("A") == ("fin", None)
    assert receiver.statistics().received == {"A": 1}


def test_a_typed_state_that_takes_the_protocols_timeout_stays_the_state_to_use() -> None:
    clock = FakeClock()
    receiver, network = setup(Endpoint, PING, {("A", "ping"): (Timing(within=10 * MS, on_expiry=True), None)},
                              "B", clock)

    class Waiting(anodize.State):  # as generated code writes a receiving state
        def recv(self) -> anodize.Message:
            return self._recv("A", ("ping", "fin"), 30)

    state = Waiting(receiver)
    clock.advance(10 * MS)
    assert state.recv() == (TIMEOUT, None)
    network.queues[("A", "B")].put(("ping", None))
    assert state.recv() == ("ping", None)
    with pytest.raises(anodize.LinearityError):
        state.recv()


@pytest.mark.parametrize("core", CORES)
def test_the_sender_is_not_held_to_a_deadline_with_else_timeout(core: type[Endpoint]) -> None:
    clock = FakeClock()
    sender, _ = setup(core, PING, {("A", "ping"): (Timing(within=10 * MS, on_expiry=True), None)}, "A", clock)
    clock.advance(1000 * MS)
    sender.send("B", "ping")
    assert clock.readings == 0  # nothing there to measure: the clock is not even read


@pytest.mark.parametrize("core", CORES)
def test_a_user_timeout_shorter_than_the_deadline_is_a_timeout_error(core: type[Endpoint]) -> None:
    receiver, _ = setup(core, PING, {("A", "ping"): (Timing(within=60_000 * MS), None)}, "B")
    with pytest.raises(TimeoutError):
        receiver.recv("A", 0.01)


EITHER = "global G(A, B, C) = (A -> B : go. end || C -> B : halt. end)"


@pytest.mark.parametrize("core", CORES)
def test_recv_any_ends_at_the_earliest_deadline_of_the_parallel_branches_it_waits_for(core: type[Endpoint]) -> None:
    constraints = {("A", "go"): (Timing(within=60_000 * MS), None), ("C", "halt"): (Timing(within=30 * MS), None)}
    receiver, network = setup(core, EITHER, constraints, "B")
    network.queues[("A", "B")].put(("go", None))
    assert receiver.recv_any(timeout=30) == ("A", ("go", None))  # there: taken, whatever the other deadline
    with pytest.raises(DeadlineMissedError) as info:  # each branch measures from the fork
        receiver.recv_any(timeout=30)
    assert (info.value.blame, info.value.deadline_ns) == ("C", 30 * MS)


@pytest.mark.parametrize("core", CORES)
def test_recv_any_with_else_timeout_returns_the_timeout_of_the_peer_due_first(core: type[Endpoint]) -> None:
    clock = FakeClock()
    constraints = {("A", "go"): (Timing(within=20 * MS, on_expiry=True), None),
                   ("C", "halt"): (Timing(within=10 * MS, on_expiry=True), None)}
    receiver, network = setup(core, EITHER, constraints, "B", clock)
    receiver.fork()  # the branches start (and measure from) here
    clock.advance(15 * MS)
    assert receiver.recv_any(timeout=30) == ("C", (TIMEOUT, None))
    clock.advance(6 * MS)
    assert receiver.recv_any(timeout=30) == ("A", (TIMEOUT, None))
    network.queues[("C", "B")].put(("halt", None))
    assert receiver.recv_any(timeout=30) == ("C", ("halt", None))


# ---- what it costs, what it reports ---------------------------------------------------------

def test_unconstrained_steps_keep_their_exact_types_and_read_no_clock() -> None:
    clock = FakeClock()
    sender, _ = setup(Endpoint, "global G(A, B) = mu t. A -> B : { num(int). t, fin. end }", {}, "A", clock)
    monitor = sender._monitor
    assert monitor is not None and not monitor.rules
    assert all(step[6] is None and step[4] for row in monitor.sends for step in row.values())
    for x in range(5):
        sender.send("B", "num", x)
    assert clock.readings == 0
    assert monitor.recv_peers == monitor.receives_from


def test_a_deadline_state_is_left_out_of_the_compiled_cores_blocking_receive() -> None:
    receiver, _ = setup(Endpoint, PING, {("A", "ping"): (Timing(within=10 * MS), None)}, "B")
    monitor = receiver._monitor
    assert monitor is not None
    assert monitor.recv_peers[monitor.state] == frozenset() and monitor.receives_from[monitor.state] == {"A"}
    ping = monitor.recvs[monitor.state][("A", "ping")]
    assert ping[6] is not None and not ping[4] and not ping[5]


@pytest.mark.parametrize("core", CORES)
def test_statistics_count_the_checks_and_keep_the_closest_margin(core: type[Endpoint]) -> None:
    clock = FakeClock()
    constrained = (Timing(every=20 * MS, jitter=2 * MS), cmp(">", at("x"), Number(0)))
    sender, _ = setup(core, STREAM, {("A", "num"): constrained}, "A", clock)
    for gap in (0, 20 * MS, 19 * MS, 21 * MS + 500_000):
        clock.advance(gap)
        sender.send("B", "num", {"x": 1})
    check = sender.statistics().constraints["!B(num(x: int)) every 20ms +- 2ms {x > 0}"]
    assert (check.checked, check.closest_ns) == (4, 500_000)


def test_a_deadline_missed_error_keeps_its_fields_between_processes() -> None:
    clock = FakeClock()
    sender, _ = setup(Endpoint, STREAM, {("A", "num"): (Timing(within=MS), None)}, "A", clock)
    clock.advance(3 * MS)
    error = raised(sender.send, "B", "num", {"x": 1})
    copy = error_from_data(error_to_data(error))
    assert isinstance(copy, DeadlineMissedError) and str(copy) == str(error)
    assert (copy.deadline_ns, copy.late_ns, copy.kind, copy.blame) == (MS, 2 * MS, "deadline", "A")


# ---- the reference semantics against the monitor, on random timed traces --------------------

LOOP = ("global G(A, B) = mu t. A -> B : { a(x: int). t, b(x: int). B -> A : c(y: int). t, "
        "stop. end }")


@dataclass(frozen=True)
class Refinement:
    expr: Expr
    holds: Callable[[dict[str, int], dict[str, int]], bool]  # (payload, earlier) -> bool, written apart


REFINEMENTS = [
    Refinement(cmp(">", at("x"), Number(0)), lambda p, e: p["x"] > 0),
    Refinement(cmp("<=", Call("abs", (at("x"),)), Number(3)), lambda p, e: abs(p["x"]) <= 3),
    Refinement(Compare(("<=", "<"), (Number(-2), at("x"), Number(2))), lambda p, e: -2 <= p["x"] < 2),
]
ECHO = Refinement(cmp("==", at("y"), at("x")), lambda p, e: "x" in e and p["y"] == e["x"])


def reference(constraints: dict[str, tuple[Timing | None, Refinement | None]],
              trace: list[tuple[int, str, dict[str, int] | None]]) -> tuple[int, str] | None:
    """Role A of LOOP under ``constraints`` (by label), acting ``trace`` (``(when ns, label,
    payload)``, sends a, b, stop and receives c): the index and kind of the first violation
    ("deadline", "period", "refinement", "protocol"), or None if all is accepted. Written from
    timed-spec.md: the previous action is the last send or receive (the start first); within
    binds a send, and a receive (it must have arrived by then); every binds the gap between two
    sends of the interaction (a, b and stop are one choice: the previous send of any of its labels
    that has a period); a refinement reads the payload, then the latest earlier x."""
    previous = 0
    last_send: int | None = None
    earlier: dict[str, int] = {}
    waiting = False  # after b, A receives c
    for index, (when, label, payload) in enumerate(trace):
        allowed = ("c",) if waiting else ("a", "b", "stop")
        if label not in allowed:
            return index, "protocol"
        timing, refinement = constraints.get(label, (None, None))
        sending = label != "c"
        within = None if timing is None or (sending and timing.on_expiry) else timing.within
        if within is not None and when - previous > within:
            return index, "deadline"
        every = timing.every if timing is not None and sending else None
        if every is not None and last_send is not None and timing is not None and not (
                every - timing.jitter <= when - last_send <= every + timing.jitter):
            return index, "period"
        if refinement is not None and payload is not None and not refinement.holds(payload, earlier):
            return index, "refinement"
        if payload is not None and "x" in payload:
            earlier["x"] = payload["x"]
        if every is not None:
            last_send = when
        previous = when
        waiting = label == "b"
        if label == "stop":
            return None
    return None


def run_monitor(constraints: dict[str, tuple[Timing | None, Refinement | None]],
                trace: list[tuple[int, str, dict[str, int] | None]]) -> tuple[int, str] | None:
    """The monitor of A's constrained machine on ``trace``, its clock set to each action's time.
    A receive is first judged by its deadline, as the endpoint judges a wait: expired if due
    before the message's time (the message is then not there yet)."""
    gt = timed_global(LOOP, {(("B" if label == "c" else "A"), label): (timing, r.expr if r else None)
                             for label, (timing, r) in constraints.items()}, roles=["A"])
    now = [0]
    monitor = Monitor(gt.project("A").fsm(), "G", "A", lambda: now[0])
    for index, (when, label, payload) in enumerate(trace):
        now[0] = when
        try:
            if label == "c":
                due = monitor.deadline("B")
                if due is not None and due[0] < when and "B" in monitor.receives_from[monitor.state]:
                    monitor.expire("B")
                monitor.recv("B", label, payload)
            else:
                monitor.send("B", label, payload)
        except DeadlineMissedError as error:
            return index, error.kind
        except ProtocolViolationError as error:
            return index, "refinement" if error.reason.startswith("refinement") else "protocol"
        if monitor.finished:
            return None
    return None


@st.composite
def timings(draw: st.DrawFn, sending: bool) -> Timing | None:
    within = draw(st.none() | st.integers(1, 30).map(lambda n: n * MS))
    every = draw(st.none() | st.integers(5, 30).map(lambda n: n * MS)) if sending else None
    jitter = draw(st.integers(0, 4)) * MS if every is not None else 0
    if every is not None and jitter >= every:
        jitter = 0
    if within is None and every is None:
        return None
    return Timing(within=within, every=every, jitter=jitter)


@st.composite
def timed_cases(draw: st.DrawFn) -> tuple[dict[str, tuple[Timing | None, Refinement | None]],
                                          list[tuple[int, str, dict[str, int] | None]]]:
    constraints: dict[str, tuple[Timing | None, Refinement | None]] = {}
    for label in ("a", "b"):
        constraints[label] = (draw(timings(True)), draw(st.none() | st.sampled_from(REFINEMENTS)))
    constraints["c"] = (draw(timings(False)), draw(st.none() | st.just(ECHO)))
    when = 0
    trace: list[tuple[int, str, dict[str, int] | None]] = []
    waiting = False
    for _ in range(draw(st.integers(1, 12))):
        when += draw(st.integers(0, 40)) * MS + draw(st.sampled_from([0, 0, 1, -1])) * (1 if when else 0)
        label = "c" if waiting else draw(st.sampled_from(["a", "a", "b", "stop"]))
        if label == "c":
            trace.append((when, "c", {"y": draw(st.integers(-4, 4))}))
        elif label == "stop":
            trace.append((when, "stop", None))
            break
        else:
            trace.append((when, label, {"x": draw(st.integers(-4, 4))}))
        waiting = label == "b"
    return constraints, trace


@settings(max_examples=examples(400), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(timed_cases())
def test_the_monitor_accepts_exactly_the_traces_the_reference_semantics_accepts(
        case: tuple[dict[str, tuple[Timing | None, Refinement | None]], list[tuple[int, str, dict[str, int] | None]]],
) -> None:
    constraints, trace = case
    assert run_monitor(constraints, trace) == reference(constraints, trace)


# ---- whole runs on each transport: a late role, an out-of-range payload ---------------------

TRANSPORTS = [pytest.param("inproc", id="inproc"),
              pytest.param("process", id="process", marks=pytest.mark.slow),
              pytest.param("dds", id="dds", marks=pytest.mark.slow)]


def _transport(kind: str) -> Any:
    if kind == "dds":
        pytest.importorskip("cyclonedds")
        return anodize.Dds()
    return anodize.Processes() if kind == "process" else anodize.Inproc()


def _run(kind: str, controller: Callable[[anodize.Endpoint], None],
         constraints: dict[tuple[str, str], tuple[Timing | None, Expr | None]], roles: list[str]) -> anodize.RunReport:
    gt = timed_global(timed_roles.CONTROL, constraints, roles=roles)
    system = anodize.System(gt, _transport(kind))
    system.group("control").role("C", controller)
    system.group("motor").role("M", timed_roles.motor)
    return system.run(timeout=60)


# tests/anodize/test_timed_end_to_end.py runs a conforming run, a late role and an out-of-range
# payload on each transport from real .proto text; here, on threads, the same from hand-built
# machines, and on each transport only what it does not: a payload refused on arrival alone.
INPROC = TRANSPORTS[:1]
DEADLINE = {("C", "cmd"): (Timing(within=200 * MS), None)}
LIMIT = {("C", "cmd"): (None, cmp("<=", at("v"), Number(10)))}


@pytest.mark.parametrize("kind", INPROC)
def test_a_run_within_its_constraints_is_ok(kind: str) -> None:
    report = _run(kind, timed_roles.punctual, {("C", "cmd"): (Timing(within=30_000 * MS),
                                                              cmp("<=", at("v"), Number(10)))}, ["C", "M"])
    assert report.ok, report.summary()


@pytest.mark.parametrize("kind", INPROC)
def test_a_late_sender_is_blamed_by_its_own_monitor(kind: str) -> None:
    report = _run(kind, timed_roles.late, DEADLINE, ["C"])
    error = report.roles["C"].error
    assert isinstance(error, DeadlineMissedError), report.summary()
    assert (error.role, error.blame, error.kind) == ("C", "C", "deadline")


@pytest.mark.parametrize("kind", INPROC)
def test_a_late_sender_is_blamed_by_the_waiting_receiver_at_the_deadline(kind: str) -> None:
    report = _run(kind, timed_roles.late, DEADLINE, ["M"])
    error = report.roles["M"].error
    assert isinstance(error, DeadlineMissedError), report.summary()
    assert (error.role, error.blame, error.kind) == ("M", "C", "deadline")


@pytest.mark.parametrize("kind", INPROC)
def test_an_out_of_range_payload_is_refused_by_the_sender(kind: str) -> None:
    report = _run(kind, timed_roles.out_of_range, LIMIT, ["C", "M"])
    error = report.roles["C"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert (error.role, error.blame, error.reason) == ("C", "C", "refinement {v <= 10} is false for cmd {'v': 99}")


@pytest.mark.parametrize("kind", TRANSPORTS)
def test_an_out_of_range_payload_is_refused_on_arrival_blaming_the_sender(kind: str) -> None:
    report = _run(kind, timed_roles.out_of_range, LIMIT, ["M"])
    error = report.roles["M"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert (error.role, error.blame, error.reason) == ("M", "C", "refinement {v <= 10} is false for cmd {'v': 99}")


# ---- the fast check of a refinement never holds where the reference does not ----------------

def _expressions() -> st.SearchStrategy[Expr]:
    leaves: st.SearchStrategy[Expr] = st.one_of(
        st.sampled_from(["x", "y", "s", "b", "r.z", "gone"]).map(at),
        st.one_of(st.integers(-3, 3), st.sampled_from([0.5, -1.5, 0.0])).map(Number),
        st.sampled_from(["a", ""]).map(Text), st.booleans().map(Truth))

    def grow(inner: st.SearchStrategy[Expr]) -> st.SearchStrategy[Expr]:
        return st.one_of(
            st.tuples(st.sampled_from(["and", "or", "+", "-", "*", "/", "%"]), inner, inner).map(
                lambda t: Binary(t[0], t[1], t[2])),
            st.tuples(st.sampled_from(["not", "-"]), inner).map(lambda t: Unary(t[0], t[1])),
            st.lists(inner, min_size=2, max_size=3).flatmap(lambda operands: st.lists(
                st.sampled_from(["==", "!=", "<", "<=", ">", ">="]), min_size=len(operands) - 1,
                max_size=len(operands) - 1).map(lambda ops: Compare(tuple(ops), tuple(operands)))),
            st.tuples(st.sampled_from(["abs", "len"]), inner).map(lambda t: Call(t[0], (t[1],))),
            st.lists(inner, min_size=1, max_size=3).flatmap(
                lambda args: st.sampled_from(["min", "max"]).map(lambda f: Call(f, tuple(args)))))

    return st.recursive(leaves, grow, max_leaves=8)


_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-3, 3), st.sampled_from([0.5, -0.0, 2.5]),
                    st.text(max_size=2))


@settings(max_examples=examples(400), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_expressions(), st.dictionaries(st.sampled_from(["x", "y", "s", "b", "r"]), _VALUES | st.fixed_dictionaries(
    {"z": _VALUES})), st.dictionaries(st.sampled_from(["y", "gone"]), _VALUES), st.sets(st.sampled_from(["x", "y"])))
def test_the_fast_check_holds_only_where_the_reference_holds(expr: Expr, payload: dict[str, object],
                                                             earlier: dict[str, object], own: set[str]) -> None:
    from anodize._session.predicates import fast_predicate
    from sessiontypes.refine import compile_predicate

    own_fields = {name for name in own if name in payload}  # a record's fields are always there
    try:
        fast = fast_predicate(expr, own_fields)(payload, earlier)
    except Exception:  # the monitor asks the reference then
        fast = None
    reference = compile_predicate(expr)(payload, earlier)
    if fast is True:
        assert reference is None, (expr, payload, earlier)


# ---- a recorded run with constraints replays: the monitor's clock readings are given back ----

@pytest.mark.parametrize("role", ["C", "M"])
def test_a_recorded_constrained_run_replays_equal_with_the_monitors_readings(tmp_path: FilePath, role: str) -> None:
    from anodize._recording.reader import open_recording
    from anodize._recording.replay import replay

    constraints = {("C", "cmd"): (Timing(within=30_000 * MS), cmp("<=", at("v"), Number(10)))}
    gt = timed_global(timed_roles.CONTROL, constraints)
    system = anodize.System(gt)
    system.group("control").role("C", timed_roles.punctual)
    system.group("motor").role("M", timed_roles.motor)
    path = tmp_path / "run.mcap"
    report = system.run(timeout=30, taps=[anodize.Recording(path)])
    assert report.ok, report.summary()
    # Each role read its clock only through its monitor: at the start and after each of the 3
    # commands (the state they lead to has the deadline), not after stop; M also once as each
    # of its 4 deadline receives begins (stop comes in the state that waits for cmd), whether or
    # not the message was there already.
    note = next(note for note in report.notes if note.startswith("recorded "))
    assert "and 12 readings of the roles' clocks" in note, note
    with open_recording(path) as recording:
        replayed = replay(recording, gt, role, {"C": timed_roles.punctual, "M": timed_roles.motor}[role], timeout=20.0)
    assert replayed.divergence is None, replayed.text()
    assert replayed.ok or role == "M", replayed.text()  # M sends nothing: a replay of it compares nothing
    assert "ended: M returned at the end of its local type" in replayed.text() or role == "C"
    assert replayed.clock == {"C": (4, 4, 0), "M": (8, 8, 0)}[role]


def test_a_recorded_run_whose_waits_expired_replays_them_where_they_expired(tmp_path: FilePath) -> None:
    """The recording keeps where a wait expired (``else timeout``): the replay expires the same
    waits, though the messages the run had not received in time are there at once, so a role whose
    output depends on its timeouts replays equal."""
    from anodize._recording.reader import open_recording
    from anodize._recording.replay import replay

    gt = sessiontypes.loads(timed_roles.WATCH, "watch.proto").globals["W"]
    system = anodize.System(gt)
    system.group("sensing").role("S", timed_roles.stalling_sensor)
    system.group("watching").role("M", timed_roles.counting_monitor)
    path = tmp_path / "run.mcap"
    report = system.run(timeout=30, taps=[anodize.Recording(path)])
    assert report.ok, report.summary()
    taken = sum(int(c["timeouts"] or 0) for key, c in report.constraints.items() if key.startswith("M "))
    assert taken >= 6, report.constraints  # two, then four, at least
    with open_recording(path) as recording:
        replayed = replay(recording, gt, "M", timed_roles.counting_monitor, timeout=20.0)
    assert replayed.divergence is None and replayed.ok, replayed.text()
    assert "sent on M->S: 3 compared of 3 recorded" in replayed.text(), replayed.text()


# ---- the compiled core checks constrained steps itself ----------------------------------------

TIMED_STREAM = "global G(A, B) = mu t. A -> B : { num(x: float). t, fin. end }"


def test_the_compiled_core_checks_a_timed_refined_stream_itself_with_the_python_cores_outcomes(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A deadline and a refinement on a record payload: the compiled core reads the clock once
    per action, checks the deadline, the record and the predicate, and calls the monitor only
    for what it does not pass at once (a late send, a false refinement), which then raises
    exactly as on the Python core; the counters and the clock's readings are the same."""
    constraints = {("A", "num"): (Timing(within=10 * MS), cmp("<=", Call("abs", (at("x"),)), Number(1.5)))}
    script: list[tuple[int, object]] = [(1 * MS, {"x": 0.5}), (2 * MS, {"x": 1}), (3 * MS, {"x": -1.5}),
                                        (1 * MS, {"x": 2.0}), (1 * MS, {"x": True}), (1 * MS, {"x": 0.25, "y": 1}),
                                        (1 * MS, {"x": 1.0}), (11 * MS, {"x": 0.5})]

    def run(core: type[Endpoint]) -> tuple[list[object], list[object], tuple[int, int | None], int, int]:
        clock = FakeClock()
        sender, network = setup(core, TIMED_STREAM, constraints, "A", clock)
        receiver, _ = setup(core, TIMED_STREAM, constraints, "B", clock)
        receiver._in["A"] = network.queues[("A", "B")]
        sent, got = [], []
        for gap, payload in script:
            clock.advance(gap)
            try:
                sender.send("B", "num", payload)
                sent.append("sent")
                got.append(receiver.recv("A"))
            except ProtocolViolationError as error:
                sent.append((type(error).__name__, str(error)))
        check = sender.statistics().constraints
        (only,) = check.values()
        return sent, got, (only.checked, only.closest_ns), clock.readings, sender._monitor.state  # type: ignore[union-attr]

    python = run(PythonEndpoint)
    calls: list[str] = []

    def counted(name: str) -> Callable[..., None]:
        original = getattr(Monitor, name)

        def call(self: Monitor, *args: Any) -> None:
            calls.append(name)
            original(self, *args)
        return call

    for name in ("send", "recv"):
        monkeypatch.setattr(Monitor, name, counted(name))
    compiled = run(Endpoint)
    assert compiled == python
    assert python[0][:3] == ["sent"] * 3 and python[0][6] == "sent" and "deadline missed" in str(python[0][7])
    assert "abs(x) <= 1.5" in str(python[0][3]) and len(python[1]) == 4
    if Endpoint.send is not PythonEndpoint.send:  # the compiled core: the monitor saw the refused sends only
        # (a receive under a deadline on a clock other than the machine's is the Python core's, which waits)
        assert calls.count("send") == sum(outcome != "sent" for outcome in python[0]), calls


def run_endpoint(core: type[Endpoint], constraints: dict[str, tuple[Timing | None, Refinement | None]],
                 trace: list[tuple[int, str, dict[str, int] | None]]) -> tuple[tuple[int, str] | None, int, object]:
    """``run_monitor`` through an endpoint of role A on ``core``, its clock set to each action's
    time: the first violation as ``reference`` gives it, the clock's readings, the statistics. A
    receive due before the message's time finds nothing there: its wait ends at once, expired."""
    clock = FakeClock()
    start = clock.t
    gt_constraints = {(("B" if label == "c" else "A"), label): (timing, r.expr if r else None)
                      for label, (timing, r) in constraints.items()}
    endpoint, network = setup(core, LOOP, gt_constraints, "A", clock, roles=["A"])
    monitor = endpoint._monitor
    assert monitor is not None
    found: tuple[int, str] | None = None
    for index, (when, label, payload) in enumerate(trace):
        clock.t = start + when / 1e9
        try:
            if label == "c":
                due = monitor.deadline("B")
                if due is None or due[0] >= to_nanos(clock.t) or "B" not in monitor.receives_from[monitor.state]:
                    network.queues[("B", "A")].put((label, payload))
                endpoint.recv("B", timeout=0 if due is None else None)
            else:
                endpoint.send("B", label, payload)
        except DeadlineMissedError as error:
            found = index, error.kind
            break
        except ProtocolViolationError as error:
            found = index, "refinement" if error.reason.startswith("refinement") else "protocol"
            break
        if monitor.finished:
            break
    return found, clock.readings, endpoint.statistics().constraints


@settings(max_examples=examples(300), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(timed_cases())
def test_both_cores_accept_exactly_the_traces_the_reference_semantics_accepts(
        case: tuple[dict[str, tuple[Timing | None, Refinement | None]], list[tuple[int, str, dict[str, int] | None]]],
) -> None:
    """The endpoint's compiled core checks most constrained steps itself (the clock read once,
    the deadline, the refinement): on random timed traces it agrees with the reference semantics
    and with the Python core, down to the clock's readings and the statistics."""
    constraints, trace = case
    compiled = run_endpoint(Endpoint, constraints, trace)
    assert compiled[0] == reference(constraints, trace)
    assert compiled == run_endpoint(PythonEndpoint, constraints, trace)
