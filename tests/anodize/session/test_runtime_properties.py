"""Properties of the in-process runtime (endpoint, monitor, inproc transport, supervisor).

Generated protocols come from ``tests/sessiontypes/strategies.py``; the roles
are :class:`role_drivers.RoleDriver` instances that walk their own projection.

- conformance: roles that follow their projections always finish (``report.ok``),
  and every channel delivers what was sent, in order;
- deviation: a role attempting a send its local type does not allow gets a
  ``ProtocolViolationError`` blaming itself, is reported failed with it, and the
  message never reaches anyone;
- transparency: with and without monitors, the same choices deliver the same
  messages in the same order on every channel;
- then the failure cases one at a time (peer failure, early return, timeout,
  payload sorts, receiving from the wrong peer, failure containment in a
  parallel composition).

Nothing here asserts on wall-clock time; timeouts only bound a broken run.
"""

from __future__ import annotations

import re
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from budget import examples
from hypothesis import HealthCheck, assume, event, given, note, settings
from hypothesis import strategies as st

_HERE = Path(__file__).resolve().parents[1]
for _folder in (_HERE, _HERE.parent / "sessiontypes"):  # helper modules, no packages
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))

from role_drivers import BOGUS_LABEL, build_system, can_always_end, distances, load_global, machines_of  # noqa: E402
from strategies import GeneratedGlobal, global_protocols  # noqa: E402

import sessiontypes  # noqa: E402
from anodize import Action, Endpoint, PeerFailedError, ProtocolViolationError, RunReport, System  # noqa: E402
from sessiontypes import GlobalType  # noqa: E402

# Keeps this file at about 20 s on two cores; raise max_examples locally for a campaign.
SETTINGS = settings(deadline=None, max_examples=examples(100),
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.filter_too_much])
RUN_TIMEOUT = 20.0  # only a broken run gets near this

seeds = st.integers(0, 2**32 - 1)


def _global(text: str, name: str = "G") -> GlobalType:
    return sessiontypes.loads(text, "test.proto").globals[name]


def _terminating(generated: GeneratedGlobal) -> GlobalType:
    """The generated global, when every role can always reach ``end`` (else rejected)."""
    note(generated.text)
    global_type = load_global(generated.text)
    machines = machines_of(global_type)
    assume(all(can_always_end(m) for m in machines.values()))
    event(f"roles: {len(global_type.roles)}")
    event("a role forks" if any(m.forks for m in machines.values()) else "no fork")
    event("a role waits on several peers (recv_any)" if any(m.waits_on_several() for m in machines.values())
          else "every receive names its peer")
    return global_type


def _run(system: System, timeout: float = RUN_TIMEOUT) -> RunReport:
    report = system.run(timeout=timeout)
    note(report.summary())
    return report


def _counts(report: RunReport) -> dict[str, int]:
    return {channel: n for channel, n in report.messages.items() if n}


# ---- (a) conformance ----------------------------------------------------------------------

@pytest.mark.slow
@SETTINGS
@given(global_protocols(), seeds)
def test_roles_that_follow_their_projections_finish(generated: GeneratedGlobal, seed: int) -> None:
    global_type = _terminating(generated)
    system, recorder, _ = build_system(global_type, seed)
    report = _run(system)
    total = sum(report.messages.values())
    event(f"messages: {'<5' if total < 5 else '<20' if total < 20 else '<100' if total < 100 else '>=100'}")
    assert report.ok, report.summary()
    assert {r.status for r in report.groups.values()} == {"done"}
    # every channel delivered exactly what was sent, in order
    assert recorder.received == recorder.sent
    assert _counts(report) == {f"{a}->{b}": len(items)
                               for (a, b), items in recorder.nonempty(recorder.sent).items()}


@pytest.mark.slow
@settings(SETTINGS, max_examples=examples(8))
@given(global_protocols(), seeds)
def test_loops_without_exit_are_stopped_at_the_timeout(generated: GeneratedGlobal, seed: int) -> None:
    """Protocols where some role can never reach ``end``: nothing fails, those roles
    are stopped, and the run is not ok. Drivers pause before each send (no spinning)."""
    note(generated.text)
    global_type = load_global(generated.text)
    machines = machines_of(global_type)
    endless = [r for r, m in machines.items() if distances(m)[m.initial] == float("inf")]
    assume(endless)
    system, _, drivers = build_system(global_type, seed)
    for driver in drivers.values():
        driver.pause = 0.002
    report = _run(system, timeout=0.3)
    assert {r.status for r in report.roles.values()} <= {"done", "stopped"}
    assert all(r.error is None for r in report.roles.values())
    assert all(report.roles[r].status == "stopped" for r in endless)
    assert not report.ok


# ---- (b) deviation ------------------------------------------------------------------------

@pytest.mark.slow
@SETTINGS
@given(global_protocols(), seeds, st.data())
def test_a_deviating_role_is_blamed_and_its_message_never_delivered(
        generated: GeneratedGlobal, seed: int, data: st.DataObject) -> None:
    global_type = _terminating(generated)
    role = data.draw(st.sampled_from(global_type.roles), label="deviator")
    at = data.draw(st.integers(0, 15), label="at action")
    system, recorder, drivers = build_system(global_type, seed, deviator=(role, at))
    report = _run(system)

    attempt = drivers[role].attempt
    assert attempt is not None
    note(f"attempt: {attempt}")
    event("wrong label" if attempt.label == BOGUS_LABEL else "wrong peer or not a sending state")
    error = attempt.error
    assert isinstance(error, ProtocolViolationError), repr(error)
    assert (error.role, error.blame) == (role, role)
    assert (error.actual.kind, error.actual.peer, error.actual.label) == ("send", attempt.peer,
                                                                          attempt.label)
    assert report.roles[role].status == "failed"
    assert report.roles[role].error is error
    assert not report.ok

    # nothing of the rejected send left: counts are the accepted sends, and the
    # intended receiver got a prefix of those
    channel = (role, attempt.peer)
    assert report.messages.get(f"{role}->{attempt.peer}", 0) == len(recorder.sent[channel])
    received = recorder.received[channel]
    assert received == recorder.sent[channel][:len(received)]
    if attempt.label == BOGUS_LABEL:
        assert all(label != BOGUS_LABEL for items in recorder.received.values() for label, _ in items)

    # everybody else finished, or was told that a peer failed: nobody is left waiting
    for other, outcome in report.roles.items():
        if other != role:
            assert outcome.status in ("done", "failed"), (other, outcome)
            assert outcome.status == "done" or isinstance(outcome.error, PeerFailedError), (other, outcome)


# ---- (c) transparency ---------------------------------------------------------------------

@pytest.mark.slow
@settings(SETTINGS, max_examples=examples(50))
@given(global_protocols(), seeds)
def test_monitors_do_not_change_what_is_delivered(generated: GeneratedGlobal, seed: int) -> None:
    global_type = _terminating(generated)
    runs = {}
    for monitored in (True, False):
        system, recorder, _ = build_system(global_type, seed, monitored=monitored)
        report = _run(system)
        assert report.ok, report.summary()
        runs[monitored] = (recorder.nonempty(recorder.received), _counts(report))
    assert runs[True] == runs[False]


# ---- failures, one at a time ----------------------------------------------------------------

def test_a_blocked_receiver_learns_that_its_peer_failed() -> None:
    global_type = _global("global G = A -> B : x(int). B -> A : y")
    waiting = threading.Event()

    def a(ep: Endpoint) -> None:
        waiting.wait(10)
        raise RuntimeError("A crashed")

    def b(ep: Endpoint) -> None:
        waiting.set()
        ep.recv("A")

    system = System(global_type)
    system.group("ga").role("A", a)
    system.group("gb").role("B", b)
    report = system.run(timeout=10)
    assert report.roles["A"].status == "failed"
    assert isinstance(report.roles["A"].error, RuntimeError)
    error = report.roles["B"].error
    assert report.roles["B"].status == "failed"
    assert isinstance(error, PeerFailedError)
    assert (error.role, error.peer) == ("B", "A")
    assert str(error) == "role B: peer A failed (RuntimeError: A crashed)"


def test_returning_before_end_is_a_violation() -> None:
    global_type = _global("global G = A -> B : x. A -> B : y")
    system = System(global_type)
    system.group("ga").role("A", lambda ep: ep.send("B", "x"))
    system.group("gb").role("B", lambda ep: (ep.recv("A"), ep.recv("A")))
    report = system.run(timeout=10)
    error = report.roles["A"].error
    assert report.roles["A"].status == "failed"
    assert isinstance(error, ProtocolViolationError)
    assert (error.role, error.blame, error.actual) == ("A", "A", Action("end", None, ""))
    assert error.expected == (Action("send", "B", "y"),)
    assert str(error) == ("protocol G, role A: protocol violation by A; in state 1 (!B(y)) "
                          "expected !B(y), got end (the role's function returned) (test.proto:1:24)")
    assert isinstance(report.roles["B"].error, PeerFailedError)
    assert report.messages == {"A->B": 1}


def test_a_never_ending_recursion_is_stopped_at_the_timeout() -> None:
    global_type = _global("global G = mu t. A -> B : tick. t")

    def a(ep: Endpoint) -> None:
        while True:
            ep.send("B", "tick")
            time.sleep(0.005)

    def b(ep: Endpoint) -> None:
        while True:
            ep.recv("A")

    system = System(global_type)
    system.group("ga").role("A", a)
    system.group("gb").role("B", b)
    report = system.run(timeout=0.3)
    assert not report.ok
    assert {(r.status, r.error) for r in report.roles.values()} == {("stopped", None)}
    assert {g.status for g in report.groups.values()} == {"stopped"}


@pytest.mark.parametrize(("message", "payload", "reason"), [
    ("n(nat)", -1, "expected a payload of sort nat (>= 0), got -1"),
    ("n(nat)", 1.5, "expected a payload of sort nat, got float"),
    ("n(int)", "7", "expected a payload of sort int, got str"),
    ("n(int)", True, "expected a payload of sort int, got bool"),
    ("n(str)", None, "expected a payload of sort str, got NoneType"),
    ("n", 3, "this label carries no payload, got int"),
])
def test_a_payload_of_the_wrong_sort_is_blamed_on_the_sender(message: str, payload: object,
                                                            reason: str) -> None:
    global_type = _global(f"global G = A -> B : {message}")
    received = []
    system = System(global_type)
    system.group("ga").role("A", lambda ep: ep.send("B", "n", payload))
    system.group("gb").role("B", lambda ep: received.append(ep.recv("A")))
    report = system.run(timeout=10)
    error = report.roles["A"].error
    assert isinstance(error, ProtocolViolationError)
    assert (error.role, error.blame, error.peer, error.reason) == ("A", "A", "B", reason)
    assert error.actual == Action("send", "B", "n", None if payload is None else type(payload).__name__)
    assert re.fullmatch(rf"protocol G, role A: protocol violation by A: {re.escape(reason)}; "
                        r"in state 0 \(.*\) expected .*, got .* \(test\.proto:1:12\)", str(error))
    assert received == []
    assert report.messages == {"A->B": 0}
    assert isinstance(report.roles["B"].error, PeerFailedError)


def test_receiving_from_a_peer_the_state_does_not_expect_fails_at_once() -> None:
    """C cannot have sent anything when B asks for it (C waits for B): a runtime
    that waited instead of raising would leave B blocked until the timeout."""
    global_type = _global("global G = A -> B : x. B -> C : y. C -> B : z")
    system = System(global_type)
    system.group("ga").role("A", lambda ep: ep.send("B", "x"))
    system.group("gb").role("B", lambda ep: ep.recv("C"))
    system.group("gc").role("C", lambda ep: (ep.recv("B"), ep.send("B", "z")))
    report = system.run(timeout=10)
    error = report.roles["B"].error
    assert report.roles["B"].status == "failed"
    assert isinstance(error, ProtocolViolationError)
    assert (error.role, error.blame, error.actual) == ("B", "B", Action("recv", "C", "*"))
    assert error.expected == (Action("recv", "A", "x"),)
    # A's one send races B's failure: it is delivered, or refused because B has failed.
    a = report.roles["A"]
    assert a.status == "done" or (isinstance(a.error, PeerFailedError) and a.error.peer == "B"), a
    assert isinstance(report.roles["C"].error, PeerFailedError)


# A bounded TinManParallel (protocols/tinman.proto): each loop can quit.
BOUNDED_TINMAN = """
global Par(Joy, Control, Camera, VisOdom, Planner, Move, Gazebo) =
  ( mu c. Joy -> Control : {
        joy(int). Control -> Move : twist(int). Move -> Gazebo : twist(int). c,
        quit. Control -> Move : quit. Move -> Gazebo : quit }
  || mu p. Camera -> VisOdom : {
        image(int). VisOdom -> Planner : pose(int). Planner -> Move : path(int). p,
        quit. VisOdom -> Planner : quit. Planner -> Move : quit } )
"""


def _relay(ep: Endpoint, frm: str, to: str, data: str, out: str) -> None:
    """Forward ``data`` from ``frm`` to ``to`` as ``out`` until ``quit``."""
    while (message := ep.recv(frm)).label == data:
        ep.send(to, out, message.payload)
    ep.send(to, "quit")


def _sink(ep: Endpoint, frm: str, into: list[int]) -> None:
    while (message := ep.recv(frm)).label != "quit":
        into.append(message.payload)


def _source(ep: Endpoint, to: str, label: str, count: int, after: int = 0,
            gate: threading.Event | None = None) -> None:
    for i in range(count):
        if i == after and gate is not None:
            gate.wait(10)  # the rest goes out only after the planner's failure was seen
        ep.send(to, label, i)
    ep.send(to, "quit")


@pytest.mark.parametrize("use_fork", [True, False], ids=["fork", "routing"])
def test_a_failed_branch_leaves_the_other_branch_running(use_fork: bool) -> None:
    """The planner fails; Move's control branch, Joy, Control and Gazebo go on to the end."""
    global_type = _global(BOUNDED_TINMAN, "Par")
    rounds = 40
    planner_failed = threading.Event()
    twists: list[int] = []
    paths: list[int] = []
    seen_failure: list[PeerFailedError] = []

    def planner(ep: Endpoint) -> None:
        for _ in range(3):
            ep.send("Move", "path", ep.recv("VisOdom").payload)
        raise RuntimeError("planner crashed")

    def move(ep: Endpoint) -> None:
        def control(branch: Endpoint) -> None:
            while (message := branch.recv("Control")).label == "twist":
                branch.send("Gazebo", "twist", message.payload)
            branch.send("Gazebo", "quit")

        def path(branch: Endpoint) -> None:
            try:
                _sink(branch, "Planner", paths)
            except PeerFailedError as error:
                seen_failure.append(error)
                planner_failed.set()

        path_thread = threading.Thread(target=path, args=(ep.fork()[1] if use_fork else ep,),
                                       daemon=True)
        if use_fork:
            path_thread.start()
            control(ep.fork()[0])
        else:
            # Through the role's own endpoint, which routes each channel to its branch.
            # The first action forks it, and is made before the second thread starts.
            first = ep.recv("Control")
            path_thread.start()
            ep.send("Gazebo", "twist", first.payload)
            control(ep)
        path_thread.join()

    system = System(global_type)
    system.group("control").role("Joy", lambda ep: _source(ep, "Control", "joy", rounds, 5,
                                                           planner_failed)) \
        .role("Control", lambda ep: _relay(ep, "Joy", "Move", "joy", "twist")) \
        .role("Move", move).role("Gazebo", lambda ep: _sink(ep, "Move", twists))
    system.group("planning").role("Camera", lambda ep: _source(ep, "VisOdom", "image", rounds)) \
        .role("VisOdom", lambda ep: _relay(ep, "Camera", "Planner", "image", "pose")) \
        .role("Planner", planner)
    report = system.run(timeout=RUN_TIMEOUT)

    assert report.roles["Planner"].status == "failed"
    assert isinstance(report.roles["Planner"].error, RuntimeError)
    for role in ("Joy", "Control", "Move", "Gazebo"):
        assert report.roles[role].status == "done", report.summary()
    assert report.groups["control"].status == "done"
    assert report.groups["planning"].status == "failed"
    assert twists == list(range(rounds))
    assert paths == [0, 1, 2]
    assert [(e.role, e.peer) for e in seen_failure] == [("Move", "Planner")]
    for role in ("Camera", "VisOdom"):  # done, or told when they next sent into the failure
        outcome = report.roles[role]
        assert outcome.status == "done" or isinstance(outcome.error, PeerFailedError), outcome


PAR = "global P = ( A -> B : x(int). B -> A : y(int) || A -> C : z(int) )"


def _parallel_roles(system: System, got: dict[str, object]) -> None:
    def a(ep: Endpoint) -> None:
        left, right = ep.fork()
        thread = threading.Thread(target=lambda: right.send("C", "z", 2), daemon=True)
        thread.start()
        left.send("B", "x", 1)
        got["A"] = left.recv("B").payload
        thread.join()

    def b(ep: Endpoint) -> None:
        got["B"] = ep.recv("A").payload
        ep.send("A", "y", 3)

    system.group("g").role("A", a).role("B", b).role("C", lambda ep: got.update(C=ep.recv("A").payload))


def test_fork_with_monitors() -> None:
    got: dict[str, object] = {}
    system = System(_global(PAR, "P"))
    _parallel_roles(system, got)
    report = system.run(timeout=10)
    assert report.ok, report.summary()
    assert got == {"A": 3, "B": 1, "C": 2}


def test_fork_works_without_monitors() -> None:
    got: dict[str, object] = {}
    system = System(_global(PAR, "P"), monitors=False)
    _parallel_roles(system, got)
    report = system.run(timeout=10)
    assert report.ok, report.summary()
    assert got == {"A": 3, "B": 1, "C": 2}


TWO_LOOPS = "global P = ( mu t. A -> B : {x(int). t, q} || mu u. A -> C : {z(int). u, q} )"


@pytest.mark.parametrize("use_fork", [True, False], ids=["fork", "routing"])
def test_two_threads_may_start_the_branches_at_once(use_fork: bool) -> None:
    """Thread-per-branch code where both threads make the first move of their branch."""
    global_type = _global(TWO_LOOPS, "P")

    def a(ep: Endpoint) -> None:
        def branch(index: int, peer: str, label: str) -> None:
            endpoint = ep.fork()[index] if use_fork else ep
            for i in range(20):
                endpoint.send(peer, label, i)
            endpoint.send(peer, "q")

        thread = threading.Thread(target=branch, args=(1, "C", "z"), daemon=True)
        thread.start()
        branch(0, "B", "x")
        thread.join()

    def sink(ep: Endpoint) -> None:
        while ep.recv("A").label != "q":
            pass

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads often, so the window is hit within a few runs
    try:
        failures = []
        for _ in range(40):
            system = System(global_type)
            system.group("g").role("A", a).role("B", sink).role("C", sink)
            report = system.run(timeout=10)
            if not report.ok:
                failures.append(report.summary())
    finally:
        sys.setswitchinterval(interval)
    assert failures == []


def test_a_role_function_annotated_any_gets_the_endpoint() -> None:
    def a(ep: Any) -> None:
        ep.send("B", "x")

    def b(ep: Any) -> None:
        ep.recv("A")

    system = System(_global("global G = A -> B : x"))
    system.group("g").role("A", a).role("B", b)
    report = system.run(timeout=10)
    assert report.ok, report.summary()
