"""Failure policies across hosts on Zenoh (two `anodize run --host` processes on loopback, clients
of an in-process router; the supervisors over ZenohHostLink), as test_dds_policies.py on DDS:
``stop`` fails the peer elsewhere, ``restart`` restarts the set wherever its groups run, a restart
used up is a stop. (``stop-system``: test_zenoh_hosts.py.)"""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import dds_roles
import pytest
from dds_hosts import run_hosts
from zenoh_hosts import free_endpoint, open_router, write_policy_system

from anodize._supervision.report import RoleStatus

pytest.importorskip("zenoh", reason="the zenoh extra is not installed")
pytestmark = pytest.mark.slow  # Zenoh hosts in processes for seconds

TOKEN = {"ANODIZE_ZENOH_TOKEN": "shared_by_both_hosts"}


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    endpoint = free_endpoint()
    session: Any = open_router(endpoint)
    yield endpoint
    session.close()


def run(router: str, tmp_path: Path, protocol: str, name: str, groups: str,
        env: dict[str, str] | None = None) -> tuple[dict, dict]:
    system = write_policy_system(tmp_path, router, protocol, name, "z" + uuid.uuid4().hex[:12], groups)
    reports = run_hosts(system, tmp_path, {**TOKEN, **(env or {})})
    return reports["A"], reports["B"]


def test_stop_on_one_host_fails_the_peer_on_the_other_and_the_rest_runs_on(router: str, tmp_path: Path) -> None:
    a, b = run(router, tmp_path, dds_roles.STREAM_AND_TICKS, "Both", """
[groups.producing]
host = "A"
roles = { P = "dds_roles:failing_producer" }

[groups.consuming]
host = "B"
roles = { C = "dds_roles:consumer" }

[groups.ticking]
host = "B"
roles = { Q = "rejoin_roles:few_ticks", R = "dds_roles:tick_counter" }
""")
    assert a["roles"]["P"]["status"] == RoleStatus.FAILED
    assert b["roles"]["C"]["error"]["type"] == "PeerFailedError", b["roles"]
    assert b["groups"]["ticking"]["status"] == "done", b["groups"]
    assert not any("stopping every group" in note for note in a["notes"] + b["notes"])


def test_a_restart_set_spanning_hosts_restarts_as_one_incarnation(router: str, tmp_path: Path) -> None:
    a, b = run(router, tmp_path, dds_roles.STREAM, "Stream", """
[groups.producing]
host = "A"
on_failure = "restart"
max_restarts = 1
roles = { P = "dds_roles:failing_once_producer" }

[groups.consuming]
host = "B"
on_failure = "restart"
max_restarts = 1
roles = { C = "dds_roles:consumer" }
""", {"DDS_TEST_MARKER": str(tmp_path / "failed-once"), "DDS_TEST_COUNT": "300"})
    assert a["groups"]["producing"]["restarts"] == 1, a
    assert b["groups"]["consuming"]["restarts"] == 1, b
    assert a["roles"]["P"]["status"] == RoleStatus.DONE, a["roles"]
    assert b["roles"]["C"]["status"] == RoleStatus.DONE, b["roles"]  # 0..299 in order, from the new producer


def test_a_restart_used_up_on_one_host_is_a_stop_there_and_its_peer_elsewhere_fails(
        router: str, tmp_path: Path) -> None:
    a, b = run(router, tmp_path, dds_roles.STREAM, "Stream", """
[groups.producing]
host = "A"
on_failure = "restart"
max_restarts = 1
roles = { P = "dds_roles:failing_producer" }

[groups.consuming]
host = "B"
on_failure = "restart"
max_restarts = 1
roles = { C = "dds_roles:consumer" }
""")
    producing = a["groups"]["producing"]
    assert (producing["restarts"], len(producing["failures"]), producing["status"]) == (1, 2, "failed"), producing
    assert b["groups"]["consuming"]["restarts"] == 1, b["groups"]
    assert b["roles"]["C"]["error"]["type"] == "PeerFailedError", b["roles"]
