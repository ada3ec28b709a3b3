"""Time and value constraints in generated typed endpoints (``anodize project -o DIR``).

The constrained machines are made here by giving transitions their constraints (the front
end that parses them is written in parallel); the modules are generated from them, imported,
driven with test_codegen's scripted fake endpoint, and checked by ``mypy --strict`` with a
program that uses them.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from types import ModuleType

import pytest
from test_codegen import FakeEndpoint, load_module

import sessiontypes
from anodize import LinearityError, Message, ProtocolViolationError
from anodize._tools.codegen import GeneratedModule, generate_module, module_filename
from sessiontypes import StateMachine
from sessiontypes.constraints import Call, Compare, Expr, Number, Timing
from sessiontypes.constraints import Path as Name
from sessiontypes.location import Location

REPO = Path(__file__).resolve().parents[3]
LOOP = """
type Twist = "ros:geometry_msgs/msg/Twist"

global Loop(C, M, O) =
  mu t. C -> M : tick(v: float, seq: int). C -> O : drive(Twist). O -> M : pose(x: float).
        M -> C : ack(n: int). M -> O : { more. t, halt. t }
"""
MS = 1_000_000
PERIOD = Timing(every=200 * MS, jitter=20 * MS)
SPEED = Compare(("<=",), (Call("abs", (Name(("v",)),)), Number(1.5)), Location("loop.proto", 5, 30))
LIMIT = Compare(("<=",), (Call("abs", (Name(("linear", "x")),)), Number(0.5)))
ECHO = Compare(("==",), (Name(("n",)), Name(("seq",))))
WAIT = Timing(within=100 * MS, on_expiry=True)


def _constrained(machine: StateMachine) -> StateMachine:
    """``machine`` with Loop's constraints: tick's period and speed, drive's limit, pose's deadline
    (else timeout), ack's echo of seq, and the choice more/halt within 100ms else timeout."""
    for row in machine.table:
        for key, t in row.items():
            changes: dict[str, Timing | Expr | object] = {}
            if t.label == "tick":
                assert t.sort is not None and t.sort.fields is not None
                v, seq = t.sort.fields
                changes = {"timing": PERIOD, "refinement": SPEED,
                           "sort": replace(t.sort, fields=(replace(v, refinement=SPEED), seq))}
            elif t.label == "drive":
                changes = {"refinement": LIMIT}
            elif t.label in ("pose", "more", "halt"):
                changes = {"timing": WAIT}
            elif t.label == "ack":
                changes = {"refinement": ECHO}
            row[key] = replace(t, **changes)  # type: ignore[arg-type]
    return machine


def _generate(role: str) -> GeneratedModule:
    global_type = sessiontypes.loads(LOOP, "loop.proto").globals["Loop"]
    machine = _constrained(global_type.project(role).fsm())
    text = generate_module(global_type, role, source_path="loop.proto", digest="0" * 64, machine=machine)
    return GeneratedModule(module_filename("Loop", role), "Loop", role, text)


def _module(tmp_path: Path, role: str) -> ModuleType:
    return load_module(tmp_path, _generate(role))


def test_docstrings_carry_the_constraints_in_their_canonical_print() -> None:
    c, m, o = (_generate(role).text for role in ("C", "M", "O"))
    assert "Constraints: ``every 200ms +- 20ms``, ``{abs(v) <= 1.5}``." in c
    assert "Constraints: ``within 100ms else timeout``." in m
    assert "Constraints: ``{abs(linear.x) <= 0.5}``." in o
    assert "A payload for which the refinement is false is refused here, before anything is sent" in c
    assert "The refinement names an earlier payload: the endpoint's monitor checks it." in m
    assert "The endpoint's monitor checks the refinement on arrival (blaming the sender)." in m
    assert "With ``else timeout`` the deadline is the receiver's: nothing is timed on sending." in o
    assert "The endpoint's monitor checks the time constraints (``DeadlineMissedError``)." in c


def test_a_refined_parameter_is_annotated_with_its_predicate() -> None:
    c, m = _generate("C").text, _generate("M").text
    assert 'def send_tick(self, v: Annotated[float, "{abs(v) <= 1.5}"], seq: int) -> State1:' in c
    assert re.search(r'def send_drive\(self, payload: Annotated\[\w+, "\{abs\(linear.x\) <= 0.5\}"\]\)', c)
    assert "def send_ack(self, n: int) -> " in m  # the message's predicate, not the field's: in the docstring


def test_an_unconstrained_protocol_generates_what_it_did() -> None:
    global_type = sessiontypes.loads(LOOP, "loop.proto").globals["Loop"]
    text = generate_module(global_type, "C", source_path="loop.proto", digest="0" * 64)
    assert "Annotated" not in text and "_refused" not in text and "Constraints" not in text


def test_a_payload_that_breaks_its_refinement_is_refused_before_anything_is_sent(tmp_path: Path) -> None:
    c = _module(tmp_path, "C")
    endpoint = FakeEndpoint()
    start = c.Initial(endpoint)
    with pytest.raises(ProtocolViolationError) as info:
        start.send_tick(2.0, 0)
    error = info.value
    assert endpoint.sent == []
    assert (error.protocol, error.role, error.peer, error.blame) == ("Loop", "C", "M", "C")
    assert error.reason == "refinement {abs(v) <= 1.5} is false for tick {'v': 2.0, 'seq': 0}"
    assert error.location.startswith("loop.proto:5:")
    assert str(error.expected[0]) == "!M(tick(v: float, seq: int))" and str(error.actual) == "!M(tick(dict))"
    driving = start.send_tick(-1.5, 0)  # the state stayed unused: a value within the bound goes
    assert endpoint.sent == [("M", "tick", {"v": -1.5, "seq": 0})]
    with pytest.raises(LinearityError):
        start.send_tick(0.0, 0)
    assert type(driving) is c.State1


def test_a_declared_sort_is_refined_by_its_attributes(tmp_path: Path) -> None:
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Vector3 as Vector3

    c = _module(tmp_path, "C")
    endpoint = FakeEndpoint()
    driving = c.Initial(endpoint).send_tick(0.5, 1)
    fast = Twist(linear=Vector3(x=0.75, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0))
    refused = r"refinement \{abs\(linear.x\) <= 0.5\} is false for drive geometry_msgs__msg__Twist\("
    with pytest.raises(ProtocolViolationError, match=refused):
        driving.send_drive(fast)
    assert len(endpoint.sent) == 1


def test_a_refinement_naming_an_earlier_payload_is_left_to_the_monitor(tmp_path: Path) -> None:
    m = _module(tmp_path, "M")
    endpoint = FakeEndpoint(Message("tick", {"v": 0.5, "seq": 3}), Message("pose", {"x": 1.0}))
    _, waiting = m.Initial(endpoint).recv_tick()
    _, acking = waiting.recv_pose()
    acking.send_ack(4)  # seq was 3: the monitor's to refuse (it keeps what M saw), not this method's
    assert endpoint.sent == [("C", "ack", {"n": 4})]


def test_a_receive_with_else_timeout_returns_its_timeout_case_and_the_same_state(tmp_path: Path) -> None:
    m = _module(tmp_path, "M")
    endpoint = FakeEndpoint(Message("tick", {"v": 0.5, "seq": 3}), Message("timeout", None),
                            Message("pose", {"x": 1.0}))
    _, waiting = m.Initial(endpoint).recv_tick()
    expired = waiting.recv_pose()
    assert type(expired) is m.State1Timeout and type(expired.next_state) is m.State1
    assert m.State1Timeout.__match_args__ == ("next_state",)
    pose, acking = expired.next_state.recv_pose()
    assert pose == {"x": 1.0} and type(acking) is m.State2


def test_an_offer_with_else_timeout_has_a_timeout_case(tmp_path: Path) -> None:
    o = _module(tmp_path, "O")
    endpoint = FakeEndpoint(Message("drive", None), Message("timeout", None), Message("halt", None))
    _, posing = o.Initial(endpoint).recv_drive()
    deciding = posing.send_pose(1.0)
    expired = deciding.offer()
    assert type(expired).__name__.endswith("Timeout") and type(expired.next_state) is type(deciding)
    chosen = expired.next_state.offer()
    assert type(chosen).__name__.endswith("Halt")


PROGRAM = '''
"""Loop's constrained roles C and M, written against their generated states (mypy --strict)."""

from __future__ import annotations

from typing import assert_never

import loop_c
import loop_m
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Vector3 as Vector3


def control(start: loop_c.Initial) -> None:
    state = start
    for seq in range(3):
        twist = Twist(linear=Vector3(x=0.25, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0))
        ack, state = state.send_tick(0.5, seq).send_drive(twist).recv_ack()
        assert ack["n"] == seq


def move(start: loop_m.Initial) -> None:
    tick, waiting = start.recv_tick()
    while True:
        answer = waiting.recv_pose(timeout=1.0)
        match answer:
            case loop_m.State1Timeout(again):
                waiting = again
            case (pose, acking):
                acking.send_ack(tick["seq"]).select_halt()
                return
            case _:
                assert_never(answer)
'''


@pytest.mark.slow
def test_constrained_modules_and_a_program_using_them_pass_mypy_strict(tmp_path: Path, mypy_cache: Path) -> None:
    for role in ("C", "M", "O"):
        module = _generate(role)
        (tmp_path / module.filename).write_text(module.text, encoding="utf-8")
    (tmp_path / "loop_program.py").write_text(PROGRAM, encoding="utf-8")
    broken = PROGRAM.replace("state.send_tick(0.5, seq)", 'state.send_tick("fast", seq)')
    (tmp_path / "broken_loop_program.py").write_text(broken, encoding="utf-8")
    files = sorted(p.name for p in tmp_path.glob("*.py"))
    environment = {**os.environ, "MYPYPATH": os.pathsep.join((str(REPO), str(REPO / "tinman" / "src")))}
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent", "--no-color-output",
         "--no-error-summary", "--cache-dir", str(mypy_cache), *files],
        cwd=tmp_path, env=environment, capture_output=True, text=True, timeout=120)
    errors = [line for line in result.stdout.splitlines() if ": error:" in line]
    assert [e.split(":")[0] for e in errors] == ["broken_loop_program.py"], result.stdout + result.stderr
    assert 'Argument 1 to "send_tick" of "State0" has incompatible type "str"; expected "float"' in errors[0]


def test_the_predicates_written_into_a_module_build_the_protocols_own_trees() -> None:
    from anodize._tools.codegen import _expr_code
    from sessiontypes import constraints
    from sessiontypes.constraints import Binary, Text, Truth, Unary

    trees: list[Expr] = [
        SPEED, LIMIT, ECHO, Number(float("inf")), Number(-0.0), Number(10**30),
        Binary("or", Unary("not", Truth(True)), Compare(("==",), (Text('say "hi"\n\\'), Name(("a", "b"))))),
        Compare(("<=", "<"), (Number(0), Binary("%", Unary("-", Name(("p",))), Number(3)), Number(1))),
        Call("max", (Number(1), Number(2.5), Call("len", (Name(("s",)),)))),
    ]
    for tree in trees:
        assert eval(_expr_code(tree), {"_c": constraints}) == tree
