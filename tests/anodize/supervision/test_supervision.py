"""The supervision core: the same failure policies, diagnoses and reports on every transport."""

from __future__ import annotations

import inspect
import re

import policy_roles as roles
import pytest

import anodize
import sessiontypes
from anodize import PeerFailedError, Transport
from anodize._supervision.report import GroupState, RoleStatus
from anodize._supervision.supervisor import window_rates

# A ping-pong pair and an independent stream: a policy's reach shows on the stream.
POLICIES = sessiontypes.loads("""
global Policies(A, B, C, D) = (mu t. A -> B : {ping(nat). B -> A : pong(nat). t, stop}
                               || mu u. C -> D : {tick(int). u, fin})
""", "test_supervision.proto").globals["Policies"]

TRANSPORTS = [pytest.param(anodize.Inproc(), id="inproc"),
              pytest.param(anodize.Processes(), id="process", marks=pytest.mark.slow)]


def run(transport: Transport, client: object, *, a: str = "stop", b: str = "stop", max_restarts: int = 3,
        server: object = roles.server, timeout: float = 60, ticker: object = roles.ticker) -> anodize.RunReport:
    system = anodize.System(POLICIES, transport=transport)
    system.group("a", on_failure=a, max_restarts=max_restarts).role("A", client)
    system.group("b", on_failure=b, max_restarts=max_restarts).role("B", server)
    system.group("c").role("C", ticker).role("D", roles.tick_sink)
    return system.run(timeout=timeout, grace=1.0)


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_stop_ends_the_failed_group_and_its_peers_learn_of_it_the_rest_runs_on(transport: Transport) -> None:
    report = run(transport, roles.failing_client)
    assert report.roles["A"].status is RoleStatus.FAILED
    assert isinstance(report.roles["B"].error, PeerFailedError), report.summary()
    assert report.roles["B"].error.peer == "A"
    assert report.groups["c"].status is GroupState.DONE, report.summary()
    assert report.messages["C->D"] == roles.TICKS + 1 == report.received["C->D"]
    assert report.groups["a"].restarts == 0
    assert not any("stopping every group" in note for note in report.notes)


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_stop_system_stops_every_group(transport: Transport) -> None:
    report = run(transport, roles.failing_client, a="stop-system", ticker=roles.endless_ticker)
    assert report.roles["A"].status is RoleStatus.FAILED
    assert report.groups["c"].status is GroupState.STOPPED, report.summary()
    assert {report.roles["C"].status, report.roles["D"].status} == {RoleStatus.STOPPED}  # cut short
    assert "stopping every group: group a failed and its policy is stop-system" in report.notes


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_restart_starts_the_connected_groups_again(transport: Transport, tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("ANODIZE_TEST_MARKER", str(tmp_path / f"marker-{transport}"))
    report = run(transport, roles.once_failing_client, a="restart", b="restart")
    assert report.ok, report.summary()
    assert report.groups["a"].restarts == 1 and report.groups["b"].restarts == 1
    assert report.groups["c"].restarts == 0  # not connected to a: never restarted
    assert "first incarnation fails" in report.groups["a"].failures[0]
    assert report.messages["A->B"] == 6 and report.received["A->B"] == 6  # the second session's


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_restart_gives_up_after_max_restarts(transport: Transport) -> None:
    report = run(transport, roles.failing_client, a="restart", b="restart", max_restarts=2)
    group = report.groups["a"]
    assert (group.restarts, len(group.failures), group.status) == (2, 3, GroupState.FAILED), report.summary()
    assert all("the sensor is unplugged" in failure for failure in group.failures)
    assert report.groups["c"].status is GroupState.DONE


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_role_that_raises_is_reported_with_the_place_in_its_own_code(transport: Transport) -> None:
    report = run(transport, roles.failing_client)
    lines, first = inspect.getsourcelines(roles.failing_client)
    line = first + next(i for i, text in enumerate(lines) if "FAILING_LINE" in text)
    role = report.roles["A"]
    assert role.where == f"{inspect.getsourcefile(roles.failing_client)}:{line} in failing_client"
    assert role.traceback[-1] == role.where  # raised in the role itself: its frame is the innermost
    assert f"  role A: failed at {role.where}: " in report.summary()
    assert report.to_dict()["roles"]["A"]["where"] == role.where
    # B's failure happened inside the endpoint; the place shown is B's own call.
    assert re.fullmatch(r".*policy_roles\.py:\d+ in server", report.roles["B"].where)


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_timeout_names_every_blocked_role_and_what_it_waited_for(transport: Transport) -> None:
    report = run(transport, roles.ping_then_sleep, timeout=1.0)
    assert report.outcome == "stopped, no failures"
    machine = POLICIES.project("B").fsm()
    waiting = [t for t in machine.expected(machine.initial) if t.action == "recv"]
    assert [t.label for t in waiting] == ["ping", "stop"]  # B is back at its loop's start
    # Waiting for the loop's next round is not a deadlock: the report says where B waits.
    assert report.roles["B"].detail == (f"waiting at the head of its loop (state {machine.initial}) for "
                                        "?A(ping(nat)) or ?A(stop)")
    assert re.fullmatch(r"sleeping in state \d+ \(Endpoint\.sleep\)", report.roles["A"].detail)
    assert "  role B: stopped, waiting at the head of its loop (state 0) for ?A(ping(nat))" in report.summary()
    assert report.to_dict()["roles"]["B"]["detail"] == report.roles["B"].detail


def test_a_role_blocked_inside_its_loop_is_not_said_to_wait_at_its_head() -> None:
    report = run(anodize.Inproc(), roles.client, server=roles.ping_without_pong, timeout=1.0)
    machine = POLICIES.project("A").fsm()
    state = machine.step(machine.initial, "send", "B", "ping")
    assert state is not None  # A sent its ping and waits for the pong, in the loop's body
    assert report.roles["A"].detail == f"blocked in state {state.target} waiting for ?B(pong(nat))"
    assert report.roles["B"].detail.startswith("sleeping in state")


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_counts_show_what_each_group_received(transport: Transport) -> None:
    report = run(transport, roles.client)
    assert report.ok, report.summary()
    assert report.groups["a"].messages == 6 and report.groups["a"].received == 5
    assert report.groups["b"].messages == 5 and report.groups["b"].received == 6
    assert report.groups["c"].received == roles.TICKS + 1


def test_window_rates_cover_whole_windows_of_steady_running_only() -> None:
    # 100 messages a second, sampled every 0.25 s for 3 s.
    samples = [(0.25 * i, 25 * i) for i in range(13)]
    assert window_rates(samples) == [100.0, 100.0, 100.0]
    assert window_rates(samples[:4]) == []  # less than one window: no figure, not a zero
    assert window_rates([]) == []


def test_a_configuration_error_is_an_anodize_error_and_a_value_error() -> None:
    system = anodize.System(POLICIES)
    with pytest.raises(anodize.ConfigurationError, match=r"^group a: on_failure must be one of stop, "
                       r"restart, stop-system, got 'retry'$") as caught:
        system.group("a", on_failure="retry")
    assert isinstance(caught.value, ValueError) and isinstance(caught.value, anodize.AnodizeError)
