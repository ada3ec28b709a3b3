"""A ROS topic's QoS as others see it: an independent DDS participant (a stand-in ROS 2 node, plain
Cyclone) matched to anodize's writer reads the QoS it offers, and the recording's
``offered_qos_profiles`` says the same, per topic, as rosbag2 writes it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest
import qos_roles
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from dds_hosts import domain

from anodize._ros import ros_type
from anodize._transport.dds import userdata_of
from anodize._transport.dds.binding import matched_publications
from anodize._transport.dds.flow import WINDOW as CREDIT_WINDOW
from anodize._transport.dds.identity import parse_identity
from anodize._transport.dds.settings import TOKEN_ENV

pytestmark = pytest.mark.slow
HERE = Path(qos_roles.__file__).resolve().parent

SYSTEM = """\
protocol = "sense.proto"
global = "Sense"
timeout = 3
pythonpath = ["{here}"]

[transport]
kind = "dds"
domain = {domain}
run_id = "offered"
wait = 30

[groups.sensing]
roles = {{ S = "qos_roles:sensor" }}

[groups.reading]
roles = {{ R = "qos_roles:scans", C = "qos_roles:counter" }}

[ros]
domain = {domain}
topics = {{ "S->R" = "/scan" }}

[ros.qos]
"/scan" = {qos}
"""


@pytest.mark.parametrize(("qos", "offered"), [
    ('"sensor_data"', ("best_effort", "keep_last", 5, "volatile")),
    ('{ history = "keep_last", depth = 1, durability = "transient_local" }',  # a latched topic
     ("reliable", "keep_last", 1, "transient_local")),
])
def test_a_ros_node_sees_the_qos_offered_and_the_recording_keeps_it(tmp_path: Path, qos: str,
                                                                     offered: tuple[str, str, int, str]) -> None:
    number = domain()
    (tmp_path / "sense.proto").write_text(qos_roles.SENSE)
    system = tmp_path / "sense.toml"
    system.write_text(SYSTEM.format(here=HERE, domain=number, qos=qos))
    participant = DomainParticipant(number)
    kind = ros_type("sensor_msgs/msg/LaserScan")
    # The most lenient request (best effort, volatile) matches whatever a writer offers.
    reader: DataReader[object] = DataReader(participant, Topic(participant, "rt/scan", kind.idl_class()),
                                            qos=Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile,
                                                    Policy.DataRepresentation(use_cdrv0_representation=True)))
    # The writer looked at must be this run's: one of an earlier run in this test process's domain
    # (the other parameter's) can still be matched until its lease runs out. A token of its own
    # makes this run's identity known to the test.
    token = uuid.uuid4().hex
    run = subprocess.Popen([sys.executable, "-m", "anodize._tools.cli", "run", "--quiet", str(system),
                            "--record", str(tmp_path / "run.mcap")], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True,
                           env={**os.environ, "QOS_TEST_OUT": str(tmp_path), TOKEN_ENV: token})
    seen = None
    try:
        deadline = time.monotonic() + 60
        while seen is None and time.monotonic() < deadline and run.poll() is None:
            for handle in matched_publications(reader):
                data = reader.get_matched_publication_data(handle)
                identity = parse_identity(userdata_of(data.qos)) if data is not None else None
                if identity is not None and identity[:2] == (f"offered/{token}", "sensing"):
                    seen = data
            time.sleep(0.02)
        out = run.communicate(timeout=120)[0]
    finally:
        run.kill()
        run.wait()
    assert seen is not None, out
    policies = seen.qos
    reliability = "best_effort" if policies[Policy.Reliability] == Policy.Reliability.BestEffort else "reliable"
    durability = ("transient_local" if policies[Policy.Durability] == Policy.Durability.TransientLocal
                  else "volatile")
    assert (reliability, durability) == (offered[0], offered[3]), (policies, out)
    assert policies[Policy.History] == Policy.History.KeepLast(offered[2]), (policies, out)
    from mcap.reader import make_reader

    with (tmp_path / "run.mcap").open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    channels = {c.topic: c.metadata for c in summary.channels.values()}
    profile = channels["/scan"]["offered_qos_profiles"]
    expected = f"history: {offered[1]}\n  depth: {offered[2]}\n  reliability: {offered[0]}\n  durability: {offered[3]}"
    assert expected in profile, profile
    others = [meta["offered_qos_profiles"] for topic, meta in channels.items() if topic.startswith("/anodize/S/C")]
    assert others and all("history: keep_all" in p and "reliability: reliable" in p for p in others)


def test_a_keep_last_reader_that_falls_behind_loses_the_oldest_and_holds_back_nobody(tmp_path: Path) -> None:
    """R dwells 20 ms on each scan while S sends about 500 a second: its depth-1 history keeps
    only the newest, the rest are counted lost, and S is never held back by R (a lossy topic is
    outside the credits), so the reliable count to C goes on at S's pace."""
    number = domain()
    (tmp_path / "sense.proto").write_text(qos_roles.SENSE)
    system = tmp_path / "sense.toml"
    system.write_text(SYSTEM.format(here=HERE, domain=number, qos='{ history = "keep_last", depth = 1 }')
                      .replace("timeout = 3", "timeout = 5"))
    done = subprocess.run([sys.executable, "-m", "anodize._tools.cli", "run", "--quiet", str(system), "--json",
                           str(tmp_path / "report.json")], capture_output=True, text=True, timeout=180,
                          env={**os.environ, "QOS_TEST_OUT": str(tmp_path), "QOS_TEST_SLOW": "0.02"})
    out = done.stdout + done.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["outcome"] == "stopped, no failures", out
    scans = json.loads((tmp_path / "scans.json").read_text())
    # R took at most one scan per dwell (it dwells after each: their spread is at least the dwells).
    assert scans["received"] - 1 <= scans["taking_s"] / 0.02 + 1e-6, (scans, out)
    # More were lost than the sender's whole credit window: counted, S never waited for them; and
    # C, on the reliable topic, got more than R took and that window together (S went on at its pace).
    assert report["lost"]["S->R"] > CREDIT_WINDOW, out
    assert report["lost"]["S->R"] == report["messages"]["S->R"] - report["received"]["S->R"] >= scans["gaps"]
    assert report["received"]["S->C"] > report["received"]["S->R"] + CREDIT_WINDOW, out
