"""The failure policies on the network transports with every group on one host (DDS, Zenoh), as
test_supervision.py proves them on threads and pipes: the same run, the same outcomes. (Across
hosts: test_dds_policies.py, test_hosts_rejoin.py.)"""

from __future__ import annotations

import json
import uuid
from collections.abc import Iterator

import policy_roles as roles
import pytest
from dds_hosts import domain

import anodize
import sessiontypes
from anodize import PeerFailedError, Transport
from anodize._supervision.report import GroupState, RoleStatus

pytestmark = pytest.mark.slow  # each runs its groups' processes on a network transport for seconds

POLICIES = sessiontypes.loads("""
global Policies(A, B, C, D) = (mu t. A -> B : {ping(nat). B -> A : pong(nat). t, stop}
                               || mu u. C -> D : {tick(int). u, fin})
""", "test_policies_networked.proto").globals["Policies"]


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    """A Zenoh router in this process on a loopback port of its own (none without the extra)."""
    zenoh = pytest.importorskip("zenoh", reason="the zenoh extra is not installed")
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{probe.getsockname()[1]}"
    session = zenoh.open(zenoh.Config.from_json5(json.dumps(
        {"mode": "router", "listen": {"endpoints": [endpoint]}, "scouting": {"multicast": {"enabled": False}}})))
    yield endpoint
    session.close()


@pytest.fixture(params=["dds", "zenoh"])
def transport(request: pytest.FixtureRequest) -> Transport:
    run_id = "p" + uuid.uuid4().hex[:12]
    if request.param == "dds":
        pytest.importorskip("cyclonedds", reason="the dds extra is not installed")
        return anodize.Dds(domain=domain(), run_id=run_id, wait=20)
    router = request.getfixturevalue("router")
    return anodize.Zenoh(mode="client", connect=(router,), run_id=run_id, scouting=False, wait=20)


def run(transport: Transport, client: object, *, a: str = "stop", b: str = "stop",
        max_restarts: int = 3, ticker: object = roles.ticker) -> anodize.RunReport:
    system = anodize.System(POLICIES, transport=transport)
    system.group("a", on_failure=a, max_restarts=max_restarts).role("A", client)
    system.group("b", on_failure=b, max_restarts=max_restarts).role("B", roles.server)
    system.group("c").role("C", ticker).role("D", roles.tick_sink)
    return system.run(timeout=60, grace=1.0)


def test_stop_fails_the_peers_and_the_rest_runs_on(transport: Transport) -> None:
    report = run(transport, roles.failing_client)
    assert report.roles["A"].status is RoleStatus.FAILED
    assert isinstance(report.roles["B"].error, PeerFailedError), report.summary()
    assert report.groups["c"].status is GroupState.DONE, report.summary()
    assert not any("stopping every group" in note for note in report.notes)


def test_stop_system_stops_every_group(transport: Transport) -> None:
    report = run(transport, roles.failing_client, a="stop-system", ticker=roles.endless_ticker)
    assert report.roles["A"].status is RoleStatus.FAILED
    assert report.groups["c"].status is GroupState.STOPPED, report.summary()
    assert "stopping every group: group a failed and its policy is stop-system" in report.notes


def test_restart_starts_the_connected_groups_again(transport: Transport, tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("ANODIZE_TEST_MARKER", str(tmp_path / "marker"))
    report = run(transport, roles.once_failing_client, a="restart", b="restart")
    assert report.ok, report.summary()
    assert report.groups["a"].restarts == 1 and report.groups["b"].restarts == 1
    assert report.groups["c"].restarts == 0
    assert report.received["A->B"] == 6  # the second session's, nothing of the first


def test_restart_used_up_is_a_stop(transport: Transport) -> None:
    report = run(transport, roles.failing_client, a="restart", b="restart", max_restarts=1)
    group = report.groups["a"]
    assert (group.restarts, len(group.failures), group.status) == (1, 2, GroupState.FAILED), report.summary()
    assert report.groups["c"].status is GroupState.DONE
