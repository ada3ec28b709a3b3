"""A choice whose branches go to different receivers, at run time (issue 17 item 2).

B and C each learn a round's branch from A or from the other, whichever message
comes: their state machines receive from two peers at one state, they take it with
``recv_any`` (or ``recv(peer)`` when they know whom to wait for), and the
transports give them a doorbell as they do roles with parallel branches.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
import routed_roles as roles

import anodize
import sessiontypes
from anodize import Endpoint, ProtocolViolationError, Transport
from anodize._recording.reader import open_recording
from anodize._recording.verify import verify

ROUTED = sessiontypes.loads("""
global Route(A, B, C) =
  mu t. A -> {
    B : job(int). B -> C : idle. C -> A : ok. t,
    C : job(int). C -> B : work(int). B -> A : result(int). t,
    B : stop. B -> C : stop
  }
""", "route.proto").globals["Route"]

TRANSPORTS = [pytest.param(anodize.Inproc(), id="inproc"), pytest.param(anodize.Processes(), id="process")]


def run(transport: Transport, c: Callable[[Endpoint], None] = roles.worker_c, record: Path | None = None,
        ) -> anodize.RunReport:
    system = anodize.System(ROUTED, transport=transport)
    system.group("a").role("A", roles.chooser)
    system.group("b").role("B", roles.worker_b)
    system.group("c").role("C", c)
    return system.run(timeout=60, taps=[anodize.Recording(record)] if record else [])


def test_the_projections() -> None:
    assert {r: str(ROUTED.project(r)) for r in ROUTED.roles} == {
        "A": "mu t.+{!B(job(int)).?C(ok).t, !C(job(int)).?B(result(int)).t, !B(stop)}",
        "B": "mu t.&{?A(job(int)).!C(idle).t, ?C(work(int)).!A(result(int)).t, ?A(stop).!C(stop)}",
        "C": "mu t.&{?B(idle).!A(ok).t, ?A(job(int)).!B(work(int)).t, ?B(stop)}",
    }


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_roles_that_learn_from_either_peer_run_monitored(transport: Transport) -> None:
    report = run(transport)
    assert report.ok, report.summary()
    assert report.messages == {"A->B": 3, "A->C": 3, "B->C": 3, "C->A": 2, "C->B": 3, "B->A": 3}


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_role_that_knows_whom_to_wait_for_may_name_the_peer(transport: Transport) -> None:
    report = run(transport, roles.worker_c_by_peer)
    assert report.ok, report.summary()


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_send_outside_the_branch_taken_is_blamed_on_its_sender(transport: Transport) -> None:
    report = run(transport, roles.lazy_c)
    error = report.roles["C"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert (error.blame, error.actual.peer, error.actual.label) == ("C", "A", "work")


def test_the_roles_that_wait_on_two_peers_get_a_doorbell() -> None:
    machines = {r: ROUTED.project(r).fsm() for r in ROUTED.roles}
    assert [r for r, m in machines.items() if m.waits_on_several()] == ["B", "C"]


def test_a_recording_verifies(tmp_path: Path) -> None:
    path = tmp_path / "route.mcap"
    report = run(anodize.Processes(), record=path)
    assert report.ok, report.summary()
    with open_recording(path) as recording:
        result = verify(recording, ROUTED)
    assert result.conforms, result.text()
