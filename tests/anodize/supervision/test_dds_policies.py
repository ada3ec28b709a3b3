"""Failure policies that reach beyond a group act across hosts (transport="dds", one
``anodize run --host`` per host, on loopback): ``stop-system`` stops the other hosts'
groups; ``restart`` restarts the restart set wherever its groups run, as one new
incarnation that meets only its own peers."""

from __future__ import annotations

import json
from pathlib import Path

import dds_roles
import pytest
from dds_hosts import HERE, domain, finish, start_host

from anodize._supervision.report import RoleStatus

pytestmark = pytest.mark.slow  # each runs DDS hosts in processes for seconds

HEADER = """\
protocol = "system.proto"
global = "{name}"
transport = "dds"
domain = {domain}
run_id = "{run_id}"
timeout = 120
pythonpath = ["{here}"]
"""


def write(directory: Path, protocol: str, name: str, run_id: str, groups: str) -> Path:
    (directory / "system.proto").write_text(protocol + "\n")
    path = directory / "system.toml"
    path.write_text(HEADER.format(name=name, domain=domain(), run_id=run_id, here=HERE) + groups)
    return path


def run_hosts(system: Path, directory: Path, env: dict[str, str] | None = None) -> dict[str, dict]:
    hosts = {host: start_host(system, host, directory / f"{host}.json", env) for host in ("A", "B")}
    outputs = {}
    try:
        for host, process in hosts.items():
            outputs[host] = finish(process, 90)  # bounded: a host that hangs fails here
    finally:
        for process in hosts.values():
            process.kill()
            process.wait()
    reports = {}
    for host in hosts:
        path = directory / f"{host}.json"
        assert path.exists(), outputs[host]
        reports[host] = json.loads(path.read_text())
    return reports


def test_stop_system_on_one_host_stops_the_groups_of_the_other(tmp_path: Path) -> None:
    system = write(tmp_path, dds_roles.STREAM_AND_TICKS, "Both", "stopsys", """
[groups.producing]
host = "A"
on_failure = "stop-system"
roles = { P = "dds_roles:failing_producer" }

[groups.consuming]
host = "B"
roles = { C = "dds_roles:consumer" }

[groups.ticking]
host = "B"
roles = { Q = "dds_roles:ticker", R = "dds_roles:tick_counter" }
""")
    reports = run_hosts(system, tmp_path)
    a, b = reports["A"], reports["B"]
    assert a["roles"]["P"]["status"] == RoleStatus.FAILED
    assert "the producer gives up" in a["roles"]["P"]["error"]["message"]
    # Host B's ticking pair has nothing to do with P: it stopped because host A said so.
    assert any("stopping every group: group producing failed and its policy is stop-system (on host A)" in note
               for note in b["notes"]), b["notes"]
    assert b["roles"]["Q"]["status"] == RoleStatus.STOPPED, b["roles"]
    assert b["roles"]["R"]["status"] == RoleStatus.STOPPED, b["roles"]
    assert b["groups"]["ticking"]["status"] == "stopped"


def test_a_restart_set_spanning_hosts_restarts_as_one_incarnation(tmp_path: Path) -> None:
    system = write(tmp_path, dds_roles.STREAM, "Stream", "restart", """
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
    reports = run_hosts(system, tmp_path, {"DDS_TEST_MARKER": str(tmp_path / "failed-once"),
                                           "DDS_TEST_COUNT": "300"})
    a, b = reports["A"], reports["B"]
    # The second incarnations ran the whole session: the consumer saw 0..299 in order from
    # the new producer (the old one's numbers 0..4 went to the old consumer only).
    assert a["groups"]["producing"]["restarts"] == 1, a
    assert b["groups"]["consuming"]["restarts"] == 1, b
    assert a["roles"]["P"]["status"] == RoleStatus.DONE, a["roles"]
    assert b["roles"]["C"]["status"] == RoleStatus.DONE, b["roles"]
    assert any("the first incarnation fails" in failure for failure in a["groups"]["producing"]["failures"]), a
