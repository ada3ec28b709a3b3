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
from policy_checks import STOP_GROUPS, check_restarted_as_one, check_stop, check_used_up, restart_env, restart_groups
from zenoh_hosts import free_endpoint, open_router, write_policy_system

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
    check_stop(*run(router, tmp_path, dds_roles.STREAM_AND_TICKS, "Both", STOP_GROUPS))


def test_a_restart_set_spanning_hosts_restarts_as_one_incarnation(router: str, tmp_path: Path) -> None:
    groups = restart_groups("dds_roles:failing_once_producer")
    check_restarted_as_one(*run(router, tmp_path, dds_roles.STREAM, "Stream", groups, restart_env(tmp_path)))


def test_a_restart_used_up_on_one_host_is_a_stop_there_and_its_peer_elsewhere_fails(
        router: str, tmp_path: Path) -> None:
    check_used_up(*run(router, tmp_path, dds_roles.STREAM, "Stream", restart_groups("dds_roles:failing_producer")))
