"""Failure policies that reach beyond a group act across hosts (transport="dds", one
``anodize run --host`` per host, on loopback): ``stop-system`` stops the other hosts'
groups; ``restart`` restarts the restart set wherever its groups run, as one new
incarnation that meets only its own peers."""

from __future__ import annotations

import json
from pathlib import Path

import dds_roles
import pytest
from dds_hosts import HERE, domain, finish, run_hosts, start_host
from policy_checks import (
    STOP_GROUPS,
    check_restarted_as_one,
    check_stop,
    check_used_up,
    restart_env,
    restart_groups,
    stop_system_groups,
)

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


def test_stop_system_on_one_host_stops_the_groups_of_the_other(tmp_path: Path) -> None:
    system = write(tmp_path, dds_roles.STREAM_AND_TICKS, "Both", "stopsys", stop_system_groups())
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
    system = write(tmp_path, dds_roles.STREAM, "Stream", "restart", restart_groups("dds_roles:failing_once_producer"))
    a, b = run_hosts(system, tmp_path, restart_env(tmp_path)).values()
    check_restarted_as_one(a, b)
    assert any("the first incarnation fails" in failure for failure in a["groups"]["producing"]["failures"]), a


def test_the_same_host_started_twice_stops_the_run_naming_both_claimants(tmp_path: Path) -> None:
    # Split brain: `anodize run --host A` on two machines (here, twice on one). Both supervisors
    # and B's stop, every report saying so; neither A keeps streaming (without the hellos, both
    # passed their barriers and ran on until B's consumer failed at its own).
    system = write(tmp_path, dds_roles.STREAM, "Stream", "twice", """
[groups.producing]
host = "A"
roles = { P = "dds_roles:slow_producer" }

[groups.consuming]
host = "B"
roles = { C = "dds_roles:consumer" }
""")
    runs = {name: start_host(system, name[0], tmp_path / f"{name}.json")
            for name in ("B", "A1", "A2")}
    try:
        outputs = {name: finish(process, 90) for name, process in runs.items()}
    finally:
        for process in runs.values():
            process.kill()
            process.wait()
    reports = {name: json.loads((tmp_path / f"{name}.json").read_text()) for name in runs}
    for name, report in reports.items():
        assert any("split brain" in note for note in report["notes"]), (name, report["notes"], outputs[name])
    # Each A names both claimants: itself and the other (by the pid of its supervisor, `anodize run`).
    a1, a2 = reports["A1"], reports["A2"]
    named = [note for note in a1["notes"] + a2["notes"] if "claimed by two supervisors" in note]
    assert any(f"pid {runs['A1'].pid}" in note and f"pid {runs['A2'].pid}" in note for note in named), named
    assert {a1["groups"]["producing"]["status"], a2["groups"]["producing"]["status"]} <= {"failed", "stopped"}


def test_stop_on_one_host_fails_the_peer_on_the_other_and_the_rest_runs_on(tmp_path: Path) -> None:
    system = write(tmp_path, dds_roles.STREAM_AND_TICKS, "Both", "stop", STOP_GROUPS)
    check_stop(*run_hosts(system, tmp_path).values())


def test_a_restart_used_up_on_one_host_is_a_stop_there_and_its_peer_elsewhere_fails(tmp_path: Path) -> None:
    system = write(tmp_path, dds_roles.STREAM, "Stream", "usedup", restart_groups("dds_roles:failing_producer"))
    check_used_up(*run_hosts(system, tmp_path).values())
