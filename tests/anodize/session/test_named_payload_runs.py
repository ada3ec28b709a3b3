"""Named payloads (``quote(price: nat, where: Point, by: str)``) and multicasts at run time.

A named payload is a ``dict`` with exactly the message's field names; both monitors check it
field by field and a misfit names the field. It travels between processes as a dict (a
declared class inside it travels as that class does), and recordings of it verify.
"""

from __future__ import annotations

from pathlib import Path

import named_payload_roles as roles
import pytest

import anodize
import sessiontypes
from anodize import PeerFailedError, ProtocolViolationError, Transport
from anodize._recording.reader import open_recording
from anodize._recording.verify import verify
from anodize._session.monitor import Monitor
from anodize._session.payloads import exact_types_for, validator_for

QUOTES = sessiontypes.loads("""
type Point = "payload_roles:Point"
global Quotes(S, A, B) =
  S -> A, B : quote(price: nat, where: Point, by: str).
  A -> S : bid(price: nat, note: str).
  S -> A, B : {sold(price: nat), unsold}
""", "quotes.proto").globals["Quotes"]

TRANSPORTS = [pytest.param(anodize.Inproc(), id="inproc"), pytest.param(anodize.Processes(), id="process")]
WANTED = "a dict with the fields price: nat, where: Point, by: str"


def quote_sort() -> sessiontypes.Sort:
    sort = next(t.sort for t in QUOTES.project("A").fsm().all_transitions() if t.label == "quote")
    assert sort is not None
    return sort


def run(transport: Transport, seller: object, record: Path | None = None) -> anodize.RunReport:
    system = anodize.System(QUOTES, transport=transport)
    system.group("s").role("S", seller)
    system.group("a").role("A", roles.buyer)
    system.group("b").role("B", roles.watcher)
    return system.run(timeout=60, taps=[anodize.Recording(record)] if record else [])


# Each payload and the reason it is refused with (the table is the specification).
MISFITS: list[tuple[object, str | None]] = [
    (dict(roles.QUOTE), None),
    ({"by": "Sam", "where": roles.Point(1, 2.5), "price": 0}, None),  # keys in any order
    ({**roles.QUOTE, "price": "120"}, "field price: expected a payload of sort nat, got str"),
    ({**roles.QUOTE, "price": -1}, "field price: expected a payload of sort nat (>= 0), got -1"),
    ({**roles.QUOTE, "where": (1, 2.5)},
     "field where: expected a payload of sort Point (payload_roles:Point), got tuple"),
    ({**roles.QUOTE, "where": roles.Point("1", 2.5)}, "field where: field x of Point: expected int, got str '1'"),
    ({"price": 120, "by": "Sam"}, f"field where is missing (expected {WANTED})"),
    ({**roles.QUOTE, "extra": 1, "more": 2}, f"unexpected fields 'extra', 'more' (expected {WANTED})"),
    ((120, roles.Point(1, 2.5), "Sam"), f"expected {WANTED}, got tuple"),
    (None, f"expected {WANTED}, got NoneType"),
]


@pytest.mark.parametrize(("payload", "reason"), MISFITS)
def test_a_named_payload_is_checked_field_by_field(payload: object, reason: str | None) -> None:
    assert validator_for(quote_sort())(payload) == reason
    assert exact_types_for(quote_sort()) == frozenset()  # never the fast path


def test_both_monitors_name_the_field_and_blame_the_sender() -> None:
    sender = Monitor(QUOTES.project("S").fsm(), "Quotes", "S")
    receiver = Monitor(QUOTES.project("A").fsm(), "Quotes", "A")
    bad = {"price": 120, "by": "Sam"}
    with pytest.raises(ProtocolViolationError) as sent:
        sender.send("A", "quote", bad)
    assert (sent.value.blame, sent.value.role) == ("S", "S")
    assert sent.value.reason == f"field where is missing (expected {WANTED})"
    assert str(sent.value.expected[0]) == "!A(quote(price: nat, where: Point, by: str))"
    assert sent.value.location == "quotes.proto:4:3"
    with pytest.raises(ProtocolViolationError) as received:
        receiver.recv("S", "quote", bad)
    assert (received.value.blame, received.value.role) == ("S", "A")


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_named_payloads_and_multicasts_run(transport: Transport) -> None:
    report = run(transport, roles.seller)
    assert report.ok, report.summary()


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize(("seller", "reason"), [
    (roles.wrong_field_seller, "field price: expected a payload of sort nat, got str"),
    (roles.missing_field_seller, f"field where is missing (expected {WANTED})"),
    (roles.wrong_nested_field_seller, "field where: field x of Point: expected int, got str '1'"),
])
def test_a_misfit_is_the_senders_violation_and_nothing_is_sent(transport: Transport, seller: object,
                                                               reason: str) -> None:
    report = run(transport, seller)
    error = report.roles["S"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert (error.blame, error.role, error.reason, error.actual.label) == ("S", "S", reason, "quote")
    assert isinstance(report.roles["A"].error, PeerFailedError), report.summary()


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_misfit_that_bypassed_the_senders_monitor_is_caught_on_arrival(transport: Transport) -> None:
    report = run(transport, roles.smuggling_seller)
    error = report.roles["A"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert (error.blame, error.role, error.reason) == ("S", "A", f"unexpected field 'extra' (expected {WANTED})")


def test_a_recording_of_named_payloads_verifies(tmp_path: Path) -> None:
    path = tmp_path / "quotes.mcap"
    report = run(anodize.Processes(), roles.seller, record=path)
    assert report.ok, report.summary()
    with open_recording(path) as recording:
        result = verify(recording, QUOTES)
    assert result.conforms, result.text()
    assert sorted(result.channels) == ["A->S", "S->A", "S->B"]
