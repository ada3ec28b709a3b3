"""Zenoh across two `anodize run --host` processes on loopback, through an in-process router: a host
killed is reported to its blocked peer within a bound (a receiver as PeerFailure, a sender as
PeerFailedError); stop-system across hosts (the supervisors
over ZenohHostLink); the system file's [zenoh] table."""

from __future__ import annotations

import json
import os
import signal
import time
import uuid
from pathlib import Path

import dds_roles
import pytest
from dds_hosts import finish, run_hosts, start_host, wait_for_group, wait_until_flowing
from policy_checks import stop_system_groups
from zenoh_hosts import free_endpoint, open_router, write_policy_system, write_system

import anodize
from anodize import PeerFailedError
from anodize._supervision.report import RoleStatus
from anodize._tools.config import ConfigError, load_config

pytest.importorskip("zenoh", reason="the zenoh extra is not installed")


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_a_killed_host_is_reported_to_its_blocked_peer_within_two_leases_and_a_margin(tmp_path: Path) -> None:
    endpoint = free_endpoint()
    router = open_router(endpoint)
    system = write_system(tmp_path, endpoint, "slow_producer", "k" + uuid.uuid4().hex[:12])
    env = {"DDS_TEST_FLOWING": str(tmp_path / "flowing"), "ANODIZE_ZENOH_TOKEN": "shared_by_both_hosts"}
    consumer = start_host(system, "B", tmp_path / "b.json", env)
    producer = start_host(system, "A", tmp_path / "a.json", env)
    try:
        group = wait_for_group(producer, 60)
        wait_until_flowing(tmp_path / "flowing", producer)  # past the start barrier
        os.kill(group, signal.SIGKILL)
        killed_at = time.monotonic()
        out = finish(consumer, 30)  # bounded: a hang fails here
        noticed_after = time.monotonic() - killed_at
    finally:
        for process in (producer, consumer):
            process.kill()
            process.wait()
        router.close()
    report = json.loads((tmp_path / "b.json").read_text())
    role = report["roles"]["C"]
    assert role["status"] == RoleStatus.FAILED, out
    assert role["error"]["type"] == PeerFailedError.__name__, out
    assert "group producing on host A" in role["error"]["message"], out
    print(f"the kill was noticed after {noticed_after:.2f} s (lease 1 s)")


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_a_killed_receiver_fails_its_blocked_sender_with_peer_failed(tmp_path: Path) -> None:
    endpoint = free_endpoint()
    router = open_router(endpoint)
    system = write_system(tmp_path, endpoint, "producer", "r" + uuid.uuid4().hex[:12], consumer="slow_consumer")
    progress = tmp_path / "consumed"
    progress.write_text("0")
    env = {"DDS_TEST_COUNT": "1000000", "DDS_TEST_PROGRESS": str(progress),
           "ANODIZE_ZENOH_TOKEN": "shared_by_both_hosts"}
    producer = start_host(system, "A", tmp_path / "a.json", env)
    consumer = start_host(system, "B", tmp_path / "b.json", env)
    try:
        group = wait_for_group(consumer, 60)
        deadline = time.monotonic() + 60
        while progress.read_text() in ("", "0") and time.monotonic() < deadline:  # past the barrier
            time.sleep(0.05)
        os.kill(group, signal.SIGKILL)  # the producer is held back by credits by now (2 ms a message there)
        out = finish(producer, 30)  # bounded: a hang fails here
    finally:
        for process in (producer, consumer):
            process.kill()
            process.wait()
        router.close()
    report = json.loads((tmp_path / "a.json").read_text())
    role = report["roles"]["P"]
    assert role["status"] == RoleStatus.FAILED, out
    assert role["error"]["type"] == PeerFailedError.__name__, out
    assert "group consuming on host B" in role["error"]["message"], out


def system_file(tmp_path: Path, zenoh: str, transport: str = 'kind = "zenoh"') -> Path:
    path = tmp_path / "system.toml"
    path.write_text(f'protocol = "p.proto"\nglobal = "G"\n\n[transport]\n{transport}\n\n{zenoh}\n'
                    '[groups.a]\nhost = "robot"\nroles = { A = "m:a" }\n\n[groups.b]\nhost = "base"\n'
                    'roles = { B = "m:b" }\n')
    return path


def test_a_system_file_with_zenoh_parses(tmp_path: Path) -> None:
    config = load_config(system_file(tmp_path, '[zenoh]\nmode = "client"\nconnect = ["tcp/10.0.0.1:7447"]\n'
                                               'scouting = false\n\n[zenoh.hosts.robot]\n'
                                               'connect = ["tcp/192.168.1.1:7447", "udp/192.168.1.2:7447"]\n',
                                     'kind = "zenoh"\nrun_id = "fleet"\nlease = 0.5\noutage = 10\nwait = 5'))
    transport = config.transport
    assert transport.kind == "zenoh"
    assert (transport.mode, transport.connect, transport.scouting) == ("client", ("tcp/10.0.0.1:7447",), False)
    assert (transport.run_id, transport.lease, transport.outage, transport.wait) == ("fleet", 0.5, 10.0, 5.0)
    assert transport.hosts == (("robot", "client", ("tcp/192.168.1.1:7447", "udp/192.168.1.2:7447"), ()),)


def test_run_transport_zenoh_takes_the_zenoh_table(tmp_path: Path) -> None:
    config = load_config(system_file(tmp_path, '[zenoh]\nmode = "client"\nconnect = ["tcp/10.0.0.1:7447"]\n',
                                     'kind = "process"\nliveness = 3.0'))
    assert config.transport.kind == "process"
    moved = config.on_transport("zenoh").transport
    assert (moved.kind, moved.mode, moved.connect, moved.liveness) == ("zenoh", "client", ("tcp/10.0.0.1:7447",), 3.0)


@pytest.mark.parametrize(("zenoh", "transport", "key", "problem"), [
    ('[zenoh]\nmode = "router"\n', 'kind = "zenoh"', "zenoh.mode", 'expected "peer" or "client", got \'router\''),
    ('[zenoh]\nconnect = "tcp/10.0.0.1:7447"\n', 'kind = "zenoh"', "zenoh.connect",
     'expected an array of Zenoh endpoints such as ["tcp/10.0.0.1:7447"], got \'tcp/10.0.0.1:7447\''),
    ('[zenoh]\nconnect = ["10.0.0.1:7447"]\n', 'kind = "zenoh"', "zenoh.connect",
     "expected Zenoh endpoints such as \"tcp/10.0.0.1:7447\" (protocol/address), got '10.0.0.1:7447'"),
    ('[zenoh]\nmode = "client"\n', 'kind = "zenoh"', "zenoh.connect",
     'mode "client": expected the endpoints of one or more routers, got none'),
    ('[zenoh]\nport = 7447\n', 'kind = "zenoh"', "zenoh.port", "unknown key; expected one of connect, hosts"),
    ('[zenoh.hosts.robot]\nmode = "server"\n', 'kind = "zenoh"', "zenoh.hosts.robot.mode",
     'expected "peer" or "client", got \'server\''),
    ("", 'kind = "zenoh"\nmode = "client"', "transport.mode", "mode is a key of [zenoh]: write zenoh.mode"),
    ("", 'kind = "zenoh"\nlease = 0', "transport.lease", "expected a number of seconds > 0, got 0"),
    ("", 'kind = "zenoh"\noutage = -1', "transport.outage", "expected a number of seconds >= 0, got -1"),
])
def test_bad_zenoh_values_are_named_with_what_was_expected(tmp_path: Path, zenoh: str, transport: str, key: str,
                                                           problem: str) -> None:
    with pytest.raises(ConfigError) as raised:
        load_config(system_file(tmp_path, zenoh, transport))
    assert f"{key}: " in str(raised.value) and problem in str(raised.value), str(raised.value)


@pytest.mark.slow  # Zenoh hosts in processes for seconds
def test_stop_system_on_one_host_stops_the_groups_of_the_other_over_zenoh(tmp_path: Path) -> None:
    endpoint = free_endpoint()
    router = open_router(endpoint)
    run_id = "s" + uuid.uuid4().hex[:12]
    system = write_policy_system(tmp_path, endpoint, dds_roles.STREAM_AND_TICKS, "Both", run_id,
                                 stop_system_groups())
    try:
        reports = run_hosts(system, tmp_path, {"ANODIZE_ZENOH_TOKEN": "shared_by_both_hosts"})
    finally:
        router.close()
    a, b = reports["A"], reports["B"]
    assert a["roles"]["P"]["status"] == RoleStatus.FAILED
    # Host B's ticking pair has nothing to do with P: it stopped because host A said so, over Zenoh.
    assert any("stopping every group: group producing failed and its policy is stop-system (on host A)" in note
               for note in b["notes"]), b["notes"]
    assert b["roles"]["Q"]["status"] == RoleStatus.STOPPED, b["roles"]
    assert b["groups"]["ticking"]["status"] == "stopped"


@pytest.mark.slow  # Zenoh hosts in processes for seconds
def test_a_restart_set_spanning_hosts_restarts_as_one_incarnation_over_zenoh(tmp_path: Path) -> None:
    endpoint = free_endpoint()
    router = open_router(endpoint)
    system = write_policy_system(tmp_path, endpoint, dds_roles.STREAM, "Stream", "r" + uuid.uuid4().hex[:12], """
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
""")
    try:
        reports = run_hosts(system, tmp_path, {"DDS_TEST_MARKER": str(tmp_path / "failed-once"),
                                               "DDS_TEST_COUNT": "300", "ANODIZE_ZENOH_TOKEN": "shared_by_both_hosts"})
    finally:
        router.close()
    a, b = reports["A"], reports["B"]
    # The new incarnations met each other only: the consumer saw 0..299 in order from the new
    # producer (the old producer's 0..4 went to the old consumer, whose writer is not accepted now).
    assert a["groups"]["producing"]["restarts"] == 1, a
    assert b["groups"]["consuming"]["restarts"] == 1, b
    assert a["roles"]["P"]["status"] == RoleStatus.DONE, a["roles"]
    assert b["roles"]["C"]["status"] == RoleStatus.DONE, b["roles"]


@pytest.mark.parametrize(("fields", "message"), [
    ({"mode": "router"}, 'Zenoh mode: expected "peer" or "client", got \'router\''),
    ({"mode": "client"}, 'Zenoh mode "client": expected the endpoints of one or more routers in connect, got none'),
    ({"connect": ("10.0.0.1",)}, "Zenoh connect: expected Zenoh endpoints such as \"tcp/10.0.0.1:7447\", got"),
    ({"lease": 0}, "Zenoh lease: expected a number of seconds > 0, got 0"),
    ({"outage": -1.0}, "Zenoh outage: expected a number of seconds >= 0, got -1.0"),
    ({"outage": float("nan")}, "Zenoh outage: expected a number of seconds >= 0, got nan"),
    ({"lease": float("inf")}, "Zenoh lease: expected a number of seconds > 0, got inf"),
    ({"run_id": "a/b"}, "Zenoh run_id: expected up to 64 letters, digits, '_', '.' or '-', got 'a/b'"),
    ({"hosts": (("robot", "server", (), ()),)}, 'Zenoh hosts robot: mode: expected "peer" or "client", got \'server\''),
])
def test_the_zenoh_value_names_a_bad_field(fields: dict[str, object], message: str) -> None:
    with pytest.raises(anodize.ConfigurationError) as raised:
        anodize.Zenoh(**fields)  # type: ignore[arg-type]
    assert message in str(raised.value), str(raised.value)
