"""The in-process runtime: monitored endpoints, channels, supervisor, report."""

from __future__ import annotations

import os
import re
import threading

import pytest

import anodize
import sessiontypes
from anodize import Endpoint, PeerFailedError, ProtocolViolationError

PING = sessiontypes.loads("""
global Ping(A, B) = mu t. A -> B : {ping(nat). B -> A : pong(nat). t, stop}
""", "ping.proto").globals["Ping"]


def client(rounds: int):
    def run(ep: Endpoint) -> None:
        for i in range(rounds):
            ep.send("B", "ping", i)
            assert ep.recv("A" if False else "B") == anodize.Message("pong", i + 1)
        ep.send("B", "stop")
    return run


def server(ep: Endpoint) -> None:
    while True:
        message = ep.recv("A")
        if message.label == "stop":
            return
        ep.send("A", "pong", message.payload + 1)


def run(global_type: sessiontypes.GlobalType, timeout: float = 10, **roles) -> anodize.RunReport:
    system = anodize.System(global_type)
    group = system.group("all")
    for name, function in roles.items():
        group.role(name, function)
    return system.run(timeout=timeout)


def test_a_conforming_run_is_ok_and_counts_messages() -> None:
    report = run(PING, A=client(5), B=server)
    assert report.ok, report.summary()
    assert report.messages == {"A->B": 6, "B->A": 5}
    assert report.roles["A"].status == report.roles["B"].status == "done"
    assert report.groups["all"].status == "done"


def test_forbidden_send_blames_the_sender_and_delivers_nothing() -> None:
    def bad(ep: Endpoint) -> None:
        ep.send("B", "pong", 1)

    received: list[object] = []

    def listener(ep: Endpoint) -> None:
        try:
            received.append(ep.recv("A"))
        except PeerFailedError as error:
            received.append(error)

    report = run(PING, A=bad, B=listener)
    error = report.roles["A"].error
    assert isinstance(error, ProtocolViolationError)
    assert (error.role, error.blame, error.peer, error.protocol) == ("A", "A", "B", "Ping")
    assert str(error) == (
        "protocol Ping, role A: protocol violation by A; in state 0 (+B{ping(nat).?B(pong(nat)).t, stop}) "
        "expected !B(ping(nat)), !B(stop), got !B(pong(int)) (ping.proto:2:27)")
    assert report.messages["A->B"] == 0
    assert len(received) == 1 and isinstance(received[0], PeerFailedError)
    assert received[0].peer == "A"


def test_wrong_payload_sort_is_a_violation_by_the_sender() -> None:
    def negative(ep: Endpoint) -> None:
        ep.send("B", "ping", -1)

    report = run(PING, A=negative, B=server)
    error = report.roles["A"].error
    assert isinstance(error, ProtocolViolationError)
    assert error.reason == "expected a payload of sort nat (>= 0), got -1"
    assert report.roles["B"].status == "failed"


def test_receiving_from_a_role_not_expected_now_fails_at_once() -> None:
    def confused(ep: Endpoint) -> None:
        ep.recv("B")

    report = run(PING, A=confused, B=server, timeout=30)
    error = report.roles["A"].error
    assert isinstance(error, ProtocolViolationError)
    assert error.blame == "A" and str(error.actual) == "?B(*)"


def test_returning_before_the_end_is_a_violation() -> None:
    def quitter(ep: Endpoint) -> None:
        ep.send("B", "ping", 1)

    report = run(PING, A=quitter, B=server)
    error = report.roles["A"].error
    assert isinstance(error, ProtocolViolationError)
    assert error.actual.kind == "end"
    assert [str(a) for a in error.expected] == ["?B(pong(nat))"]


def test_an_endless_loop_is_stopped_not_passed() -> None:
    forever = sessiontypes.loads("global F = mu t. A -> B : tick. t").globals["F"]

    def ticker(ep: Endpoint) -> None:
        while True:
            ep.send("B", "tick")
            threading.Event().wait(0.01)

    def listener(ep: Endpoint) -> None:
        while True:
            ep.recv("A")

    report = run(forever, timeout=0.3, A=ticker, B=listener)
    assert not report.ok
    assert {r.status for r in report.roles.values()} == {"stopped"}


def test_a_crashed_peer_is_reported_to_a_blocked_receiver() -> None:
    def crash(ep: Endpoint) -> None:
        raise RuntimeError("sensor unplugged")

    report = run(PING, A=crash, B=server, timeout=30)
    assert report.roles["A"].status == "failed"
    error = report.roles["B"].error
    assert isinstance(error, PeerFailedError)
    assert str(error) == "role B: peer A failed (RuntimeError: sensor unplugged)"


def test_roles_must_exist_and_be_placed_once() -> None:
    system = anodize.System(PING)
    group = system.group("g")
    with pytest.raises(ValueError, match=re.escape("global Ping has no role C; expected one of A, B")):
        group.role("C", server)
    group.role("A", client(1))
    with pytest.raises(ValueError, match="role A is already in group g"):
        system.group("h").role("A", server)
    with pytest.raises(anodize.AnodizeError, match="roles B are in no group"):
        system.run(timeout=1)


def test_scheduling_is_applied_or_the_fallback_is_reported() -> None:
    system = anodize.System(PING)
    system.group("fast", priority=60).role("A", client(2))
    system.group("slow").role("B", server)
    report = system.run(timeout=10)
    assert report.ok
    scheduling = report.groups["fast"].scheduling
    assert scheduling == "SCHED_FIFO 60" or re.fullmatch(r"nice -?\d+ \(SCHED_FIFO refused: .+\)|unchanged .+",
                                                         scheduling)
    assert report.groups["slow"].scheduling == "SCHED_OTHER (no priority asked)"


def test_refused_real_time_falls_back_to_nice(monkeypatch: pytest.MonkeyPatch) -> None:
    from anodize._isolation.sched import apply_thread_scheduling

    monkeypatch.setenv("ANODIZE_NO_RT", "1")
    result: list[str] = []
    worker = threading.Thread(target=lambda: result.append(apply_thread_scheduling(1)))
    worker.start()
    worker.join()
    assert result == ["nice 19 (SCHED_FIFO refused: disabled by ANODIZE_NO_RT)"]


PARALLEL = sessiontypes.loads("""
global Split(C, M, P, G) =
  ( mu c. C -> M : {go(int). M -> G : go(int). c, done. M -> G : done}
  || mu p. P -> M : {plan(str). p, done} )
""", "split.proto").globals["Split"]


def test_parallel_branches_fail_separately() -> None:
    def controller(ep: Endpoint) -> None:
        for i in range(3):
            ep.send("M", "go", i)
        ep.send("M", "done")

    def planner(ep: Endpoint) -> None:
        ep.send("M", "plan", "p0")
        raise RuntimeError("planner crashed")

    seen: list[str] = []

    def mixer(ep: Endpoint) -> None:
        control, planning = ep.fork()

        def plans() -> None:
            try:
                while planning.recv("P").label == "plan":
                    seen.append("plan")
            except PeerFailedError:
                seen.append("planner failed")

        thread = threading.Thread(target=plans)
        thread.start()
        while (message := control.recv("C")).label == "go":
            control.send("G", "go", message.payload)
        control.send("G", "done")
        thread.join()

    def gazebo(ep: Endpoint) -> None:
        while ep.recv("M").label == "go":
            pass

    report = run(PARALLEL, C=controller, M=mixer, P=planner, G=gazebo)
    assert report.roles["P"].status == "failed"
    assert [report.roles[r].status for r in ("C", "M", "G")] == ["done", "done", "done"]
    assert seen == ["plan", "planner failed"]


def test_recv_any_takes_whichever_branch_is_ready() -> None:
    def controller(ep: Endpoint) -> None:
        ep.send("M", "go", 1)
        ep.send("M", "done")

    def planner(ep: Endpoint) -> None:
        ep.send("M", "plan", "p")
        ep.send("M", "done")

    labels: list[tuple[str, str]] = []

    def mixer(ep: Endpoint) -> None:
        finished = 0
        while finished < 2:
            peer, message = ep.recv_any(timeout=10)
            labels.append((peer, message.label))
            if message.label == "go":
                ep.send("G", "go", message.payload)
            elif message.label == "done":
                if peer == "C":
                    ep.send("G", "done")
                finished += 1

    def gazebo(ep: Endpoint) -> None:
        while ep.recv("M").label == "go":
            pass

    report = run(PARALLEL, C=controller, M=mixer, P=planner, G=gazebo)
    assert report.ok, report.summary()
    assert sorted(labels) == [("C", "done"), ("C", "go"), ("P", "done"), ("P", "plan")]


@pytest.mark.skipif(os.geteuid() != 0, reason="a negative nice value needs root (CAP_SYS_NICE) here")
@pytest.mark.parametrize("transport", [anodize.Inproc(), anodize.Processes()], ids=["inproc", "process"])
def test_a_group_with_a_nice_value_runs_its_roles_at_it(transport: anodize.Transport, tmp_path, monkeypatch) -> None:
    import json

    import nice_roles

    monkeypatch.setenv(nice_roles.VARIABLE, str(tmp_path / "seen.json"))
    system = anodize.System(sessiontypes.loads(nice_roles.PROTOCOL, "told.proto").globals["Told"],
                            transport=transport)
    system.group("world", nice=-7).role("A", "nice_roles:measurer")
    system.group("sink").role("B", "nice_roles:writer")
    report = system.run(timeout=20)
    assert report.ok, report.summary()
    seen = json.loads((tmp_path / "seen.json").read_text())
    assert seen == {"policy": os.SCHED_OTHER, "nice": -7}
    assert report.groups["world"].scheduling == "SCHED_OTHER nice -7"


@pytest.mark.parametrize(("settings", "message"), [
    ({"nice": 20}, "nice must be an int -20..19, got 20"),
    ({"nice": True}, "nice must be an int -20..19, got True"),
    ({"nice": -5, "priority": 30}, "priority 30 .SCHED_FIFO. and nice -5 .ordinary scheduling. exclude each other"),
])
def test_a_nice_value_is_checked_where_the_group_is_declared(settings: dict, message: str) -> None:
    with pytest.raises(anodize.ConfigurationError, match=message):
        anodize.System(PING).group("g", **settings)
