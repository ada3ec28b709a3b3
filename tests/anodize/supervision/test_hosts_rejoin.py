"""A host cut off and back (issue 32): two network namespaces, the link between them taken down
and brought up again, with host A's producer pausing meanwhile (it touches no channel, so only
its supervisor can learn what happened). Needs root."""

from __future__ import annotations

import json
import signal
import time
from collections.abc import Iterator
from pathlib import Path

import dds_roles
import pytest
from dds_hosts import HERE, Hosts, domain, finish, namespaces_unavailable, start_host, wait_until_flowing
from policy_checks import restart_groups
from rejoin_checks import (
    BOTH,
    MEET,
    PAUSING,
    heard_the_stop_it_missed,
    restarted_as_decided_without_it,
    told_the_run_moved_on,
)

REASON = namespaces_unavailable()
pytestmark = [pytest.mark.slow, pytest.mark.skipif(REASON is not None, reason=REASON or "")]

HEADER = """\
protocol = "system.proto"
global = "{name}"
transport = "dds"
domain = {domain}
run_id = "{run_id}"
timeout = 120
pythonpath = ["{here}"]
"""

CUT_FOR = 6.0  # seconds the link is down: past both supervisors' lost_after (3 s) and the lease (1 s)


@pytest.fixture
def hosts() -> Iterator[Hosts]:
    made = Hosts()
    try:
        made.create()
        yield made
    finally:
        made.delete()


def run_with_a_cut(hosts: Hosts, tmp_path: Path, protocol: str, name: str, groups: str,
                   interrupt_b: bool = False) -> tuple[dict, dict, str]:
    """B, then A; once A's producer has sent its first message, cut the link for CUT_FOR seconds,
    then restore it; both hosts' reports (B interrupted once A has ended, when asked)."""
    (tmp_path / "system.proto").write_text(protocol + "\n")
    system = tmp_path / "system.toml"
    system.write_text(HEADER.format(name=name, domain=domain(), run_id=name.lower() + str(tmp_path.name[-6:]),
                                    here=HERE) + groups)
    env = {"REJOIN_MARKER": str(tmp_path / "paused-once"), "REJOIN_FLOWING": str(tmp_path / "flowing"),
           "REJOIN_PAUSE": "40", "DDS_TEST_COUNT": "100"}
    b = start_host(system, "B", tmp_path / "b.json", env, namespace=hosts.b)
    a = start_host(system, "A", tmp_path / "a.json", env, namespace=hosts.a)
    try:
        wait_until_flowing(tmp_path / "flowing", a)
        time.sleep(MEET)  # the supervisors meet: nothing to poll (no word says so outside them)
        hosts.cut()
        time.sleep(CUT_FOR)  # the partition: nothing to poll, the test waits it out
        hosts.restore()
        out = "A:\n" + finish(a, 60)  # bounded: before, A ran on until its producer's pause ended
        if interrupt_b:
            b.send_signal(signal.SIGINT)
        out += "B:\n" + finish(b, 60)
    finally:
        for process in (a, b):
            process.kill()
            process.wait()
    return json.loads((tmp_path / "a.json").read_text()), json.loads((tmp_path / "b.json").read_text()), out


def test_stop_a_host_back_from_a_cut_is_told_the_run_moved_on_and_stops(hosts: Hosts, tmp_path: Path) -> None:
    a, b, out = run_with_a_cut(hosts, tmp_path, dds_roles.STREAM_AND_TICKS, "Both",
                               BOTH.format(cut="A", mover="B", policy="stop", more=""), interrupt_b=True)
    told_the_run_moved_on(a, b, "A", "B", out)


def test_restart_used_up_a_host_back_from_a_cut_is_told_the_run_moved_on_and_stops(
        hosts: Hosts, tmp_path: Path) -> None:
    # The consumer's restart is used up (max_restarts = 0): a stop, and A, back, hears as much.
    a, b, out = run_with_a_cut(hosts, tmp_path, dds_roles.STREAM_AND_TICKS, "Both",
                               BOTH.format(cut="A", mover="B", policy="restart", more="max_restarts = 0"),
                               interrupt_b=True)
    told_the_run_moved_on(a, b, "A", "B", out)
    assert b["groups"]["consuming"]["restarts"] == 0, out


def test_stop_system_a_host_back_from_a_cut_hears_the_stop_it_missed(hosts: Hosts, tmp_path: Path) -> None:
    a, b, out = run_with_a_cut(hosts, tmp_path, dds_roles.STREAM_AND_TICKS, "Both",
                               BOTH.format(cut="A", mover="B", policy="stop-system", more=""))
    heard_the_stop_it_missed(a, b, "B", out)


def test_restart_a_host_back_from_a_cut_restarts_as_the_incarnation_decided_without_it(
        hosts: Hosts, tmp_path: Path) -> None:
    a, b, out = run_with_a_cut(hosts, tmp_path, dds_roles.STREAM, "Stream", restart_groups(PAUSING, "A", "B"))
    restarted_as_decided_without_it(a, b, "B", out)
