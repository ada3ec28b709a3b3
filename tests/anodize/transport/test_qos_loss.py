"""A best-effort topic over a link that really loses packets: nftables (``numgen random``) drops a
fifth of the UDP datagrams leaving a network namespace's loopback, where a whole run goes on. The
lossy stream loses messages, the report counts them, no monitor calls it a violation, and the
reliable channel beside it loses nothing. Needs root (as test_dds_hosts.py)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import qos_roles
from dds_hosts import domain, namespaces_unavailable

HERE = Path(qos_roles.__file__).resolve().parent


REASON = namespaces_unavailable(needs_nft=True)
pytestmark = [pytest.mark.slow, pytest.mark.skipif(REASON is not None, reason=REASON or "")]


def sh(*argv: str) -> None:
    subprocess.run(argv, check=True, capture_output=True, timeout=30)


class LossyHost:
    """A network namespace whose loopback (multicast on, for Cyclone's discovery) drops
    ``percent`` % of the UDP datagrams sent on it, at random."""

    def __init__(self, percent: int) -> None:
        self.name = f"anz-q-{os.getpid()}"
        sh("ip", "netns", "add", self.name)
        sh("ip", "-n", self.name, "link", "set", "lo", "up", "multicast", "on")
        for command in ("add table inet lossy", "add chain inet lossy out { type filter hook output priority 0; }",
                        (f'add rule inet lossy out oifname "lo" meta l4proto udp numgen random mod 100 < {percent} '
                         "counter drop")):
            sh("ip", "netns", "exec", self.name, "nft", command)

    def dropped(self) -> int:
        listing = subprocess.run(["ip", "netns", "exec", self.name, "nft", "list", "table", "inet", "lossy"],
                                 capture_output=True, text=True, timeout=30).stdout
        return sum(int(n) for n in re.findall(r"counter packets (\d+)", listing))

    def delete(self) -> None:
        subprocess.run(["ip", "netns", "del", self.name], capture_output=True, timeout=30)


@pytest.fixture
def lossy_host() -> Iterator[LossyHost]:
    host = LossyHost(20)
    try:
        yield host
    finally:
        host.delete()


SYSTEM = """\
protocol = "sense.proto"
global = "Sense"
timeout = {seconds}
pythonpath = ["{here}"]

[transport]
kind = "dds"
domain = {domain}
run_id = "lossy"
wait = 30

[groups.sensing]
roles = {{ S = "qos_roles:sensor" }}

[groups.scanning]
roles = {{ R = "qos_roles:scans" }}

[groups.counting]
roles = {{ C = "qos_roles:counter" }}

[ros]
domain = {domain}
topics = {{ "S->R" = "/scan" }}

[ros.qos]
"/scan" = "sensor_data"
"""


def test_a_sensor_data_stream_over_a_lossy_link_loses_counted_messages_and_no_violation(
        lossy_host: LossyHost, tmp_path: Path) -> None:
    (tmp_path / "sense.proto").write_text(qos_roles.SENSE)
    system = tmp_path / "sense.toml"
    system.write_text(SYSTEM.format(seconds=6, here=HERE, domain=domain()))
    done = subprocess.run(["ip", "netns", "exec", lossy_host.name, sys.executable, "-m", "anodize._tools.cli", "run",
                           "--quiet", str(system), "--json", str(tmp_path / "report.json")],
                          capture_output=True, text=True, timeout=180,
                          env={**os.environ, "QOS_TEST_OUT": str(tmp_path)})
    out = done.stdout + done.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    # The run went on to its timeout: every role stopped there, none failed (no violation, nobody blamed).
    assert report["outcome"] == "stopped, no failures", out
    assert {role["status"] for role in report["roles"].values()} == {"stopped"}, out
    scans = json.loads((tmp_path / "scans.json").read_text())
    counts = json.loads((tmp_path / "counts.json").read_text())
    assert lossy_host.dropped() > 100  # the link really lost datagrams
    # The stream lost some (R saw the gaps in the numbers, each scan newer than the last) ...
    assert scans["gaps"] > 0, (scans, out)
    assert scans["received"] > 500, (scans, out)
    # ... and the report counts them, with those still in flight at the stop.
    assert report["lost"] == {"S->R": report["messages"]["S->R"] - report["received"]["S->R"]}, out
    assert report["lost"]["S->R"] >= scans["gaps"], (scans, out)
    assert f"lost {report['lost']['S->R']} of {report['messages']['S->R']} on S->R" in out
    assert "S->R may lose messages: /scan is sensor_data (best_effort, keep_last 5, volatile)" in out
    # The reliable channel beside it lost nothing: C checked every number, in order.
    assert counts["received"] == report["received"]["S->C"] > 500, (counts, out)
    assert "S->C" not in report["lost"]
