"""``transport=Processes()``: groups as OS processes, isolated, supervised, and still monitored."""

from __future__ import annotations

import glob
import os

import process_roles as roles
import pytest

import anodize
import sessiontypes
from anodize import MemoryBoundError, PeerFailedError, ProtocolViolationError
from anodize._isolation.sched import nice_for
from anodize._transport.shm import segment_dir
from anodize.errors import RoleError

PROTOCOLS = sessiontypes.loads("""
type Frame = "process_roles:Frame"
type Opaque = "process_roles:Opaque"
type Things = "builtins:dict"
type Outer = "process_roles:Outer"
global Ping(A, B) = mu t. A -> B : {ping(nat). B -> A : pong(nat). t, stop}
global Stream(A, B) = mu t. A -> B : {item(int). t, fin}
global Frames(A, B) = mu t. A -> B : {frame(Frame). t, fin}
global Payloads(A, B) = A -> B : thing(Opaque). A -> B : nested(Things)
global Where(A, B) = A -> B : where(str)
global Flood(A, B, C, D) = (mu t. A -> B : {blob(bytes). t, fin} || C -> D : hello. D -> C : bye)
global Gate(A, B, D) = D -> B : go. mu t. A -> B : {blob(bytes). t, fin}
global Nested(A, B) = A -> B : outer(Outer)
global Sleepy(A, B) = mu t. A -> B : item(int). t
global Hog(C, S, H, K) = (mu t. C -> S : {tick(int). t, done} || mu u. H -> K : {chunk(int). u, fin})
""", "test_process.proto").globals


def run(global_name: str, groups: dict[str, dict[str, object]], timeout: float = 60, **options: object
        ) -> anodize.RunReport:
    system = anodize.System(PROTOCOLS[global_name], transport=anodize.Processes())
    for name, spec in groups.items():
        spec = dict(spec)
        placed = spec.pop("roles")
        group = system.group(name, **spec)  # type: ignore[arg-type]
        for role, function in placed.items():  # type: ignore[attr-defined]
            group.role(role, function)
    return system.run(timeout=timeout, **options)  # type: ignore[arg-type]


def no_leftover_segments() -> bool:
    """No ring file of this process's runs is left (ring names start with the supervisor's pid)."""
    return not glob.glob(f"{segment_dir()}/anodize-{os.getpid()}-*")


def test_a_protocol_runs_across_processes_with_monitors_at_both_ends() -> None:
    report = run("Ping", {"a": {"roles": {"A": roles.client}}, "b": {"roles": {"B": roles.server}}})
    assert report.ok, report.summary()
    assert report.messages == {"A->B": 51, "B->A": 50}
    assert report.groups["a"].pid != report.groups["b"].pid
    assert report.transport == "process"


@pytest.mark.slow
def test_a_leak_in_a_thread_a_role_started_stops_the_group_at_its_bound() -> None:
    report = run("Hog", {
        "control": {"priority": 80, "roles": {"C": roles.steady_controller, "S": roles.steady_sensor}},
        "hog": {"memory": "64MiB", "roles": {"H": roles.hog_in_a_thread}},
        "sink": {"roles": {"K": roles.hog_sink}},
    }, timeout=30)
    assert isinstance(report.groups["hog"].error, MemoryBoundError), report.summary()
    assert report.roles["K"].error.peer == "H"  # type: ignore[union-attr]
    assert report.roles["C"].status == "done"


def test_a_role_pacing_itself_with_ep_sleep_stops_with_the_run() -> None:
    report = run("Sleepy", {"a": {"roles": {"A": roles.sleeper}}, "b": {"roles": {"B": roles.count_sink}}},
                 timeout=0.5, grace=30.0)
    assert report.roles["A"].status == "stopped", report.summary()
    assert report.outcome == "stopped, no failures"
    assert report.duration < 30  # woken by the stop: neither the 60 s sleep nor the grace period's kill


def test_dataclasses_held_in_fields_of_a_named_dataclass_cross_too() -> None:
    report = run("Nested", {"a": {"roles": {"A": roles.send_nested}}, "b": {"roles": {"B": roles.receive_nested}}})
    assert report.ok, report.summary()


@pytest.mark.slow
def test_a_million_messages_cross_in_order() -> None:
    report = run("Stream", {"a": {"roles": {"A": roles.count_source}},
                            "b": {"roles": {"B": roles.count_sink}}}, timeout=300)
    assert report.ok, report.summary()
    assert report.messages["A->B"] == roles.MESSAGES + 1


@pytest.mark.slow
def test_ten_thousand_numpy_frames_cross_through_shared_memory_intact() -> None:
    report = run("Frames", {"a": {"roles": {"A": roles.frame_source}},
                            "b": {"roles": {"B": roles.frame_sink}}}, timeout=300)
    assert report.ok, report.summary()
    assert report.messages["A->B"] == roles.FRAMES + 1
    assert no_leftover_segments()


@pytest.mark.slow
def test_a_memory_hog_is_stopped_whole_while_another_group_completes() -> None:
    report = run("Hog", {
        "control": {"priority": 80, "roles": {"C": roles.steady_controller, "S": roles.steady_sensor}},
        "hog": {"memory": "64MiB", "roles": {"H": roles.hog}},
        "sink": {"roles": {"K": roles.hog_sink}},
    })
    hog = report.groups["hog"]
    assert hog.status == "failed"
    assert isinstance(hog.error, MemoryBoundError)
    assert hog.error.bound == 64 * 2**20
    assert 32 * 2**20 < hog.error.peak <= 64 * 2**20 + 2**20
    assert isinstance(report.roles["K"].error, PeerFailedError)
    assert report.roles["K"].error.peer == "H"
    assert report.roles["C"].status == report.roles["S"].status == "done"
    assert report.messages["C->S"] == 151
    assert "MemoryBoundError" in report.summary()


def test_a_killed_group_fails_its_waiting_peer_instead_of_hanging() -> None:
    report = run("Ping", {"a": {"roles": {"A": roles.crashing_client}},
                          "b": {"roles": {"B": roles.patient_server}}}, timeout=60)
    assert report.roles["A"].status == "failed"
    assert "SIGKILL" in str(report.groups["a"].error)
    error = report.roles["B"].error
    assert isinstance(error, PeerFailedError), report.summary()  # not "stopped" at the timeout
    assert error.peer == "A" and "SIGKILL" in error.cause


def test_a_forbidden_message_injected_into_a_channel_is_rejected_and_the_sender_blamed() -> None:
    report = run("Ping", {"a": {"roles": {"A": roles.injecting_client}},
                          "b": {"roles": {"B": roles.server}}})
    error = report.roles["B"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert error.blame == "A" and error.role == "B"
    assert error.actual.label == "pong"


def test_a_frame_that_does_not_decode_is_a_violation_by_its_sender() -> None:
    report = run("Ping", {"a": {"roles": {"A": roles.garbling_client}},
                          "b": {"roles": {"B": roles.server}}})
    error = report.roles["B"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert error.blame == "A" and "could not be decoded" in str(error)


def test_restart_starts_the_failed_session_again(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("ANODIZE_TEST_MARKER", str(tmp_path / "marker"))
    report = run("Ping", {"a": {"on_failure": "restart", "roles": {"A": roles.once_failing_client}},
                          "b": {"on_failure": "restart", "roles": {"B": roles.server}}})
    assert report.ok, report.summary()
    assert report.groups["a"].restarts == 1 and report.groups["b"].restarts == 1
    assert "first incarnation fails" in report.groups["a"].failures[0]
    assert report.messages["A->B"] == 51  # the restarted session, counted on top of nothing


@pytest.mark.slow
def test_restarts_stop_after_max_restarts() -> None:
    report = run("Hog", {
        "control": {"roles": {"C": roles.steady_controller, "S": roles.steady_sensor}},
        "hog": {"memory": "32MiB", "on_failure": "restart", "max_restarts": 2,
                "roles": {"H": roles.hog, "K": roles.hog_sink}},
    })
    hog = report.groups["hog"]
    assert hog.restarts == 2 and len(hog.failures) == 3
    assert hog.status == "failed" and isinstance(hog.error, MemoryBoundError)
    assert report.roles["C"].status == "done"


def test_stop_system_stops_every_group() -> None:
    report = run("Ping", {"a": {"on_failure": "stop-system", "roles": {"A": roles.injecting_client}},
                          "b": {"roles": {"B": roles.patient_server}}}, timeout=60, grace=1.0)
    assert report.roles["B"].status in ("failed", "stopped")
    assert any("stop-system" in note for note in report.notes)


@pytest.mark.slow
def test_a_role_stuck_outside_the_protocol_is_killed_at_the_timeout() -> None:
    report = run("Ping", {"a": {"roles": {"A": roles.client}},
                          "b": {"roles": {"B": roles.sleepy_server}}}, timeout=1.0, grace=0.5)
    assert report.roles["B"].status == "stopped"
    assert report.roles["A"].status == "stopped"


def test_payloads_travel_without_pickle_except_for_named_classes() -> None:
    report = run("Payloads", {"a": {"roles": {"A": roles.opaque_sender}},
                              "b": {"roles": {"B": roles.opaque_receiver}}})
    assert report.ok, report.summary()


def test_an_unnamed_class_is_refused_at_the_sender() -> None:
    report = run("Payloads", {"a": {"roles": {"A": roles.unnamed_sender}},
                              "b": {"roles": {"B": roles.waiting_receiver}}})
    error = report.roles["A"].error
    assert isinstance(error, RoleError) and error.type_name == "PayloadError", report.summary()
    assert "process_roles.Unnamed" in str(error)
    assert isinstance(report.roles["B"].error, PeerFailedError)


def test_role_functions_must_be_importable_by_other_processes() -> None:
    system = anodize.System(PROTOCOLS["Ping"], transport=anodize.Processes())
    with pytest.raises(anodize.AnodizeError, match="no import path"):
        system.group("a").role("A", lambda ep: None)
    with pytest.raises(anodize.AnodizeError, match="cannot import"):
        system.group("b").role("B", "no_such_module_here:f")


def test_a_group_runs_pinned_with_its_priority_or_says_why_not(monkeypatch) -> None:
    monkeypatch.setenv("ANODIZE_NO_RT", "1")  # the fallback, whatever this machine permits
    monkeypatch.setenv("ANODIZE_TEST_EXPECT", f"[0] other {nice_for(60)}")
    report = run("Where", {"a": {"priority": 60, "cpus": {0}, "roles": {"A": roles.where_sender}},
                           "b": {"roles": {"B": roles.where_receiver}}})
    assert report.ok, report.summary()
    scheduling = report.groups["a"].scheduling
    assert scheduling == f"nice {nice_for(60)} (SCHED_FIFO refused: disabled by ANODIZE_NO_RT); cpus 0"


def test_a_group_gets_sched_fifo_where_the_machine_permits_it(monkeypatch) -> None:
    import os
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except PermissionError:
        pytest.skip("this machine refuses SCHED_FIFO; the fallback is tested above")
    monkeypatch.setenv("ANODIZE_TEST_EXPECT", "[0] fifo 0")
    report = run("Where", {"a": {"priority": 60, "cpus": {0}, "roles": {"A": roles.where_sender}},
                           "b": {"roles": {"B": roles.where_receiver}}})
    assert report.ok, report.summary()
    assert report.groups["a"].scheduling == "SCHED_FIFO 60; cpus 0"


@pytest.mark.slow
def test_a_sender_blocked_on_a_full_pipe_learns_that_its_receiver_failed() -> None:
    # B fails without reading while D keeps B's process alive: A must not wait for that process.
    report = run("Flood", {"a": {"roles": {"A": roles.flooding_sender}},
                           "b": {"roles": {"B": roles.failing_non_reader, "D": roles.lingering_receiver}},
                           "c": {"roles": {"C": roles.hello_sender}}}, timeout=8, grace=0.5)
    error = report.roles["A"].error
    assert isinstance(error, PeerFailedError), report.summary()
    assert error.peer == "B" and "gives up without reading" in error.cause


@pytest.mark.slow
def test_a_sender_blocked_on_a_full_pipe_is_stopped_not_failed_at_the_timeout() -> None:
    # B waits for D's go (never sent), so it stops at the timeout without taking the flood;
    # its process then exits, and A's blocked write fails: that is a stop, not a failure.
    report = run("Gate", {"a": {"roles": {"A": roles.flooding_sender}},
                          "b": {"roles": {"B": roles.stoppable_non_reader}},
                          "d": {"roles": {"D": roles.sleeping_non_reader}}}, timeout=1.5, grace=4.0)
    assert report.roles["A"].status == "stopped", report.summary()
    assert report.roles["B"].status == "stopped"


def test_an_announced_oversized_frame_is_a_violation_by_its_sender() -> None:
    report = run("Ping", {"a": {"roles": {"A": roles.huge_frame_client}},
                          "b": {"memory": "64MiB", "roles": {"B": roles.server}}})
    error = report.roles["B"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert error.blame == "A" and "byte limit" in str(error)


@pytest.mark.slow
def test_recv_any_across_processes_is_stopped_at_the_timeout() -> None:
    report = run("Ping", {"a": {"roles": {"A": roles.sleepy_server}},
                          "b": {"roles": {"B": roles.any_receiver}}}, timeout=1.0, grace=2.0)
    assert report.roles["B"].status == "stopped", report.summary()


def test_ep_sleep_for_ever_ends_with_the_run() -> None:
    report = run("Sleepy", {"a": {"roles": {"A": roles.sleep_for_ever}}, "b": {"roles": {"B": roles.count_sink}}},
                 timeout=0.5, grace=30.0)
    assert report.roles["A"].status == "stopped", report.summary()
