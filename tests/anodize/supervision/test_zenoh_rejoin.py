"""A host cut off and back over Zenoh (issue 32's failure-policy table): the robot and the base in network
namespaces of their own, joined only by a Zenoh router in a third (routed.py), each host's groups and
supervisor clients of it. The robot's link to the router is taken down long enough that the base's
supervisor loses sight of the robot's (3 s) and the peers fail by liveliness, then brought up again,
while the robot's producer pauses (it touches no channel, so only its supervisor can learn what
happened). The same supervisors' code as test_hosts_rejoin.py's on DDS, over ``ZenohHostLink``.
Needs root, namespaces and nftables; one set of namespaces and one router serve the module."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import dds_roles
import pytest
import routed
from policy_checks import restart_groups
from rejoin_checks import (
    BOTH,
    MEET,
    PAUSING,
    heard_the_stop_it_missed,
    restarted_as_decided_without_it,
    told_the_run_moved_on,
)
from routed import Routed, finish, wait_for

HERE = Path(routed.__file__).resolve().parent
REASON = routed.unavailable()
pytestmark = [pytest.mark.slow, pytest.mark.skipif(REASON is not None, reason=REASON or "")]

CUT_FOR = 6.0  # seconds the link is down: past the supervisors' lost_after (3 s) and the lease (1 s)

HEADER = """\
protocol = "system.proto"
global = "{name}"
timeout = 120
pythonpath = ["{here}"]

[transport]
kind = "zenoh"
run_id = "{run_id}"
wait = 30
lease = 1.0

[zenoh]
mode = "client"
scouting = false
connect = ["{robot}"]

[zenoh.hosts.base]
connect = ["{base}"]
"""

TOKEN = {"ANODIZE_ZENOH_TOKEN": f"rejoin-{os.getpid()}"}  # the run's secret, the same on both hosts


@pytest.fixture(scope="module")
def network() -> Iterator[Routed]:
    made = Routed()
    try:
        made.create()
        made.start_router()
        yield made
    finally:
        made.close()


@pytest.fixture
def net(network: Routed) -> Iterator[Routed]:
    """The module's network, mended after each test: its processes ended, the robot's link up."""
    first = len(network.processes)
    yield network
    network.end_processes(first)
    network.mend("robot")


def start_host(net: Routed, system: Path, host: str, env: dict[str, str]) -> subprocess.Popen[str]:
    """``anodize run SYSTEM --host HOST`` in ``host``'s namespace, its report in HOST.json beside SYSTEM."""
    return net.start(host, [sys.executable, "-m", "anodize._tools.cli", "run", "--quiet", str(system), "--host", host,
                            "--json", str(system.parent / f"{host}.json")], {**TOKEN, **env})


def run_with_a_cut(net: Routed, tmp_path: Path, protocol: str, name: str, groups: str,
                   interrupt_base: bool = False) -> tuple[dict[str, Any], dict[str, Any], str]:
    """The base, then the robot; once the robot's producer has sent its first message, cut the robot's
    link for CUT_FOR seconds, then mend it; both hosts' reports (the base interrupted once the robot
    has ended, when asked)."""
    (tmp_path / "system.proto").write_text(protocol + "\n")
    system = tmp_path / "system.toml"
    system.write_text(HEADER.format(name=name, run_id=f"{name.lower()}-{tmp_path.name[-6:]}-{os.getpid()}",
                                    here=HERE, robot=net.endpoint("robot"), base=net.endpoint("base")) + groups)
    env = {"REJOIN_MARKER": str(tmp_path / "paused-once"), "REJOIN_FLOWING": str(tmp_path / "flowing"),
           "REJOIN_PAUSE": "40", "DDS_TEST_COUNT": "100"}
    base = start_host(net, system, "base", env)
    robot = start_host(net, system, "robot", env)
    wait_for(tmp_path / "flowing", [base, robot])
    time.sleep(MEET)  # the supervisors meet: nothing to poll (no word says so outside them)
    net.cut("robot")
    time.sleep(CUT_FOR)  # the partition: nothing to poll, the test waits it out
    net.mend("robot")
    out = "robot:\n" + finish(robot, 60)  # bounded: a robot left running until its producer's pause ends fails
    if interrupt_base:
        base.send_signal(signal.SIGINT)
    out += "base:\n" + finish(base, 60)
    reports = (json.loads((tmp_path / f"{host}.json").read_text()) for host in ("robot", "base"))
    return next(reports), next(reports), out


def test_stop_a_host_back_from_a_cut_is_told_the_run_moved_on_and_stops_over_zenoh(
        net: Routed, tmp_path: Path) -> None:
    robot, base, out = run_with_a_cut(net, tmp_path, dds_roles.STREAM_AND_TICKS, "Both",
                                      BOTH.format(cut="robot", mover="base", policy="stop", more=""),
                                      interrupt_base=True)
    told_the_run_moved_on(robot, base, "robot", "base", out)


def test_restart_used_up_a_host_back_from_a_cut_is_told_the_run_moved_on_and_stops_over_zenoh(
        net: Routed, tmp_path: Path) -> None:
    # The consumer's restart is used up (max_restarts = 0): a stop, and the robot, back, hears as much.
    robot, base, out = run_with_a_cut(net, tmp_path, dds_roles.STREAM_AND_TICKS, "Both",
                                      BOTH.format(cut="robot", mover="base", policy="restart",
                                                  more="max_restarts = 0"), interrupt_base=True)
    told_the_run_moved_on(robot, base, "robot", "base", out)
    assert base["groups"]["consuming"]["restarts"] == 0, out


def test_stop_system_a_host_back_from_a_cut_hears_the_stop_it_missed_over_zenoh(net: Routed, tmp_path: Path) -> None:
    robot, base, out = run_with_a_cut(net, tmp_path, dds_roles.STREAM_AND_TICKS, "Both",
                                      BOTH.format(cut="robot", mover="base", policy="stop-system", more=""))
    heard_the_stop_it_missed(robot, base, "base", out)


def test_restart_a_host_back_from_a_cut_restarts_as_the_incarnation_decided_without_it_over_zenoh(
        net: Routed, tmp_path: Path) -> None:
    robot, base, out = run_with_a_cut(net, tmp_path, dds_roles.STREAM, "Stream",
                                      restart_groups(PAUSING, "robot", "base"))
    restarted_as_decided_without_it(robot, base, "base", out)
