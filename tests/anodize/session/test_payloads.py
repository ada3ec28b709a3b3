"""Payload checks: sorts, and the fields of dataclass payloads (issue 11), at both monitors."""

from __future__ import annotations

import enum
import numbers
from dataclasses import dataclass, field
from typing import Any, Literal, Optional

import numpy as np
import numpy.typing as npt
import payload_roles as roles
import pytest

import anodize
import sessiontypes
from anodize import PeerFailedError, ProtocolViolationError, Transport
from anodize._session.monitor import Monitor
from anodize._session.payloads import check_fields, exact_types_for, validator_for

PROTOCOLS = sessiontypes.loads("""
type Point = "payload_roles:Point"
type Track = "payload_roles:Track"
type Loose = "test_payloads:Loose"
global Points(A, B) = A -> B : point(Point). A -> B : track(Track)
global Loosely(A, B) = A -> B : loose(Loose)
""", "test_payloads.proto").globals


class Color(enum.IntEnum):
    RED = 1


@dataclass
class Inner:
    x: int
    y: float = 0.0


@dataclass
class Node:
    value: int
    next: Node | None = None


@dataclass
class Shapes:
    """One field per annotation shape the check understands."""

    i: int = 1
    f: float = 1.0
    c: complex = 0j
    s: str = ""
    b: bool = False
    by: bytes = b""
    maybe: int | None = None
    maybe_inner: Optional[Inner] = None  # noqa: UP045 (the typing spelling is checked too)
    ints: list[int] = field(default_factory=list)
    floats: tuple[float, ...] = ()
    pair: tuple[int, str] = (1, "a")
    table: dict[str, Inner] = field(default_factory=dict)
    tags: set[int] = field(default_factory=set)
    array: np.ndarray = field(default_factory=lambda: np.zeros(1))
    doubles: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(1))
    reals: npt.NDArray[np.floating[Any]] = field(default_factory=lambda: np.zeros(1, np.float32))
    anything: Any = None
    choice: Literal["a", "b"] = "a"
    inner: Inner = field(default_factory=lambda: Inner(1))
    inners: list[Inner] = field(default_factory=list)
    color: Color = Color.RED
    real: numbers.Real = 0  # any other class: isinstance, so a bool is a Real here


@dataclass
class Loose:
    """Nothing to check: it keeps the monitor's fast path."""

    anything: Any
    unannotated: object


def test_values_that_fit_their_annotations_pass() -> None:
    assert check_fields(Shapes()) is None
    assert check_fields(Shapes(i=Color.RED, f=3, c=2.5, maybe=4, maybe_inner=Inner(2), ints=[1, 2],
                               floats=(1.0, 2), table={"k": Inner(1, 2)}, tags={1}, doubles=np.ones(3),
                               reals=np.ones(2, np.float16), anything=object(), choice="b",
                               inners=[Inner(1), Inner(2)], real=True)) is None
    assert check_fields(Node(1, Node(2))) is None
    assert check_fields("not a dataclass") is None


# Each misfit and the reason it is refused with (lark's habit: the table is the specification).
MISFITS: list[tuple[dict[str, object], str]] = [
    ({"i": "a"}, "field i of Shapes: expected int, got str 'a'"),
    ({"i": True}, "field i of Shapes: expected int, got bool True"),
    ({"f": True}, "field f of Shapes: expected float, got bool True"),
    ({"f": "1"}, "field f of Shapes: expected float, got str '1'"),
    ({"c": "c"}, "field c of Shapes: expected complex, got str 'c'"),
    ({"s": 1}, "field s of Shapes: expected str, got int 1"),
    ({"b": 1}, "field b of Shapes: expected bool, got int 1"),
    ({"by": bytearray(b"x")}, "field by of Shapes: expected bytes, got bytearray bytearray(b'x')"),
    ({"maybe": 1.5}, "field maybe of Shapes: expected int | None, got float 1.5"),
    ({"maybe_inner": Inner("z")}, "field maybe_inner.x of Shapes: expected int, got str 'z'"),  # type: ignore[arg-type]
    ({"maybe_inner": 3}, "field maybe_inner of Shapes: expected Inner | None, got int 3"),
    ({"ints": [1, "x"]}, "field ints[1] of Shapes: expected int, got str 'x'"),
    ({"ints": (1,)}, "field ints of Shapes: expected list[int], got tuple (1,)"),
    ({"floats": (1.0, "a")}, "field floats[1] of Shapes: expected float, got str 'a'"),
    ({"pair": (1, 2)}, "field pair[1] of Shapes: expected str, got int 2"),
    ({"pair": (1,)}, "field pair of Shapes: expected tuple[int, str], got tuple (1,)"),
    ({"table": {"k": Inner(1.5)}}, "field table['k'].x of Shapes: expected int, got float 1.5"),  # type: ignore[arg-type]
    ({"table": {1: Inner(1)}}, "field table of Shapes: expected dict[str, Inner], got dict {1: Inner(x=1, y=0.0)}"),
    ({"tags": {"a"}}, "field tags of Shapes: expected set[int], got set {'a'}"),
    ({"array": [1]}, "field array of Shapes: expected ndarray, got list [1]"),
    ({"doubles": np.zeros(2, np.int64)}, "field doubles of Shapes: expected ndarray of float64, got ndarray of int64"),
    ({"reals": np.zeros(1, np.int8)}, "field reals of Shapes: expected ndarray of floating, got ndarray of int8"),
    ({"choice": "c"}, "field choice of Shapes: expected 'a' | 'b', got str 'c'"),
    ({"inner": Inner(x="q")}, "field inner.x of Shapes: expected int, got str 'q'"),  # type: ignore[arg-type]
    ({"inner": {"x": 1}}, "field inner of Shapes: expected Inner, got dict {'x': 1}"),
    ({"inners": [Inner(1), Inner(1, "f")]}, "field inners[1].y of Shapes: expected float, got str 'f'"),  # type: ignore[arg-type]
    ({"color": 1}, "field color of Shapes: expected Color, got int 1"),
    ({"real": 1j}, "field real of Shapes: expected Real, got complex 1j"),
]


@pytest.mark.parametrize(("fields", "reason"), MISFITS, ids=[reason.split(":")[0] for _, reason in MISFITS])
def test_a_field_that_does_not_fit_is_named_with_what_was_expected_and_what_came(
        fields: dict[str, Any], reason: str) -> None:
    assert check_fields(Shapes(**fields)) == reason


def test_nested_and_cyclic_dataclasses() -> None:
    assert check_fields(Node(1, Node(2, Node("3")))) == (  # type: ignore[arg-type]
        "field next.next.value of Node: expected int, got str '3'")
    cycle = Node(1)
    cycle.next = cycle
    assert check_fields(cycle) == "Node is nested too deeply to check (does it contain itself?)"


def test_an_unset_field_and_an_unresolvable_annotation() -> None:
    @dataclass
    class Unset:
        x: int = field(init=False)

    assert check_fields(Unset()) == "field x of Unset: expected int, got no value (the attribute was never set)"

    @dataclass
    class Unresolvable:
        x: NoSuchName  # type: ignore[name-defined]  # noqa: F821 (accepted unchecked)
        y: int

    assert check_fields(Unresolvable("anything", 1)) is None
    assert check_fields(Unresolvable("anything", "1")) == "field y of Unresolvable: expected int, got str '1'"


def test_a_dataclass_sort_no_longer_skips_its_fields_through_the_fast_path() -> None:
    points = PROTOCOLS["Points"]
    point = next(t.sort for t in points.project("A").fsm().all_transitions() if t.label == "point")
    assert exact_types_for(point) == frozenset()  # every Point takes the full check
    assert validator_for(point)(roles.Point(1, 2.0)) is None
    assert validator_for(point)(roles.Point("a", 2.0)) == "field x of Point: expected int, got str 'a'"  # type: ignore[arg-type]
    loose = next(t.sort for t in PROTOCOLS["Loosely"].project("A").fsm().all_transitions())
    assert exact_types_for(loose) == frozenset({Loose})  # nothing to check: the fast path stays


def test_a_subclass_is_checked_with_its_own_fields() -> None:
    @dataclass(frozen=True)
    class Point3(roles.Point):
        z: int = 0

    point = next(t.sort for t in PROTOCOLS["Points"].project("A").fsm().all_transitions() if t.label == "point")
    assert validator_for(point)(Point3(1, 2.0, 3)) is None
    assert validator_for(point)(Point3(1, 2.0, "3")) == "field z of Point3: expected int, got str '3'"  # type: ignore[arg-type]


def test_the_monitors_blame_the_sender_and_a_refused_send_does_not_move_the_sender_on() -> None:
    points = PROTOCOLS["Points"]
    sender = Monitor(points.project("A").fsm(), "Points", "A")
    receiver = Monitor(points.project("B").fsm(), "Points", "B")
    before = sender.state
    with pytest.raises(ProtocolViolationError) as sent:
        sender.send("B", "point", roles.Point("a", 1.0))  # type: ignore[arg-type]
    assert sender.state == before
    assert (sent.value.blame, sent.value.role) == ("A", "A")
    assert sent.value.reason == "field x of Point: expected int, got str 'a'"
    assert "protocol violation by A: field x of Point: expected int, got str 'a'; in state" in str(sent.value)
    with pytest.raises(ProtocolViolationError) as received:
        receiver.recv("A", "point", roles.Point("a", 1.0))  # type: ignore[arg-type]
    assert (received.value.blame, received.value.role) == ("A", "B")
    assert received.value.reason == "field x of Point: expected int, got str 'a'"


def run(transport: Transport, sender: object) -> anodize.RunReport:
    system = anodize.System(PROTOCOLS["Points"], transport=transport)
    system.group("a").role("A", sender)
    system.group("b").role("B", roles.receiver)
    return system.run(timeout=60)


TRANSPORTS = [pytest.param(anodize.Inproc(), id="inproc"), pytest.param(anodize.Processes(), id="process")]


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_conforming_dataclasses_pass_both_monitors(transport: Transport) -> None:
    report = run(transport, roles.good_sender)
    assert report.ok, report.summary()


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize(("sender", "reason"), [
    (roles.bad_point_sender, "field x of Point: expected int, got str 'a'"),
    (roles.bad_track_sender, "field points[1].x of Track: expected int, got str 'b'"),
])
def test_the_sender_is_blamed_and_nothing_is_sent(transport: Transport, sender: object, reason: str) -> None:
    report = run(transport, sender)
    error = report.roles["A"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert (error.blame, error.role, error.reason) == ("A", "A", reason)
    assert isinstance(report.roles["B"].error, PeerFailedError), report.summary()  # it never got the message


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize(("sender", "label", "reason"), [
    (roles.smuggling_point_sender, "point", "field x of Point: expected int, got str 'a'"),
    (roles.smuggling_track_sender, "track", "field points[1].x of Track: expected int, got str 'b'"),
])
def test_a_misfit_that_bypassed_the_senders_monitor_is_caught_on_arrival(
        transport: Transport, sender: object, label: str, reason: str) -> None:
    report = run(transport, sender)
    error = report.roles["B"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert (error.blame, error.role, error.reason, error.actual.label) == ("A", "B", reason, label)
