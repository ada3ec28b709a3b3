"""Local types compiled to deterministic state machines."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import sessiontypes
from sessiontypes.fsm import build_term_machine

ROOT = Path(__file__).resolve().parents[2]


def machine(text: str, role: str, name: str = "G") -> sessiontypes.StateMachine:
    return sessiontypes.loads(text, "m.proto").globals[name].project(role).fsm()


def run(m: sessiontypes.StateMachine, actions: list[tuple[str, str, str]]) -> int | None:
    state = m.initial
    for action, peer, label in actions:
        transition = m.step(state, action, peer, label)  # type: ignore[arg-type]
        if transition is None:
            return None
        state = transition.target
    return state


def test_sequence_states_and_end() -> None:
    m = machine("global G = A -> B : x(int). B -> A : y", "A")
    assert len(m.table) == 3
    end = run(m, [("send", "B", "x"), ("recv", "B", "y")])
    assert end is not None and m.is_final(end)
    assert run(m, [("recv", "B", "y")]) is None
    first = m.expected(m.initial)
    assert [str(t) for t in first] == ["!B(x(int))"]
    assert str(first[0].location) == "m.proto:1:12"
    assert first[0].sort is not None and first[0].sort.key == "int"


def test_recursion_loops_back_to_the_same_state() -> None:
    m = machine("global G = mu t. A -> B : {more. B -> A : ack. t, stop}", "B")
    after_ack = run(m, [("recv", "A", "more"), ("send", "A", "ack")])
    assert after_ack == m.initial
    stopped = run(m, [("recv", "A", "more"), ("send", "A", "ack"), ("recv", "A", "stop")])
    assert stopped is not None and m.is_final(stopped)
    assert m.describe(m.initial) == "&A{more.!A(ack).t, stop}"


def test_states_are_shared_by_nested_loops() -> None:
    m = machine("global G = mu t. A -> B : x. mu s. A -> B : {again. s, out. t, done}", "B")
    # x, then the choice state; 'again' and 'out' loop back to existing states
    inner = run(m, [("recv", "A", "x")])
    assert inner is not None
    assert run(m, [("recv", "A", "x"), ("recv", "A", "again")]) == inner
    assert run(m, [("recv", "A", "x"), ("recv", "A", "out")]) == m.initial
    assert len(m.table) == 3


def test_parallel_is_a_fork_with_one_machine_per_branch() -> None:
    tinman = sessiontypes.load(ROOT / "protocols" / "tinman.proto").globals["TinManParallel"]
    m = tinman.project("Move").fsm()
    forks = m.forks[m.initial]
    assert len(forks) == 4
    control, scans, estimates, planning = forks
    assert run(control, [("recv", "Control", "Twist"), ("send", "Gazebo", "Twist")]) == control.initial
    assert run(scans, [("recv", "Gazebo", "LaserScan")]) == scans.initial
    assert run(estimates, [("recv", "VisOdom", "Pose")]) == estimates.initial
    assert run(planning, [("recv", "Planner", "Path")]) == planning.initial
    assert not m.is_final(m.initial)


def test_json_and_dot_export() -> None:
    m = machine("global G = mu t. A -> B : {more(int). t, stop}", "A")
    data = json.loads(m.to_json())
    assert data["role"] == "A" and data["protocol"] == "G" and data["initial"] == 0
    transitions = data["states"][0]["transitions"]
    assert {(t["action"], t["peer"], t["label"], t["sort"]) for t in transitions} == {
        ("send", "B", "more", "int"), ("send", "B", "stop", None)}
    dot = m.to_dot()
    assert dot.startswith('digraph "G A" {')
    assert '"s0" -> "s0" [label="!B(more(int))"];' in dot


@pytest.mark.slow
def test_long_sequence_builds_without_deep_recursion() -> None:
    steps = ". ".join(f"A -> B : m{i}" for i in range(30_000))
    m = sessiontypes.loads(f"global G = {steps}").globals["G"].project("B").fsm()
    assert len(m.table) == 30_001


def test_binary_local_type_machine_has_no_peers() -> None:
    atm = sessiontypes.load(ROOT / "protocols" / "atm.proto").locals["ATM"]
    m = build_term_machine(atm.body)
    state = run(m, [("recv", None, "Int"), ("send", None, "ok"), ("recv", None, "deposit"),  # type: ignore[list-item]
                    ("recv", None, "Int")])
    assert state == m.initial
