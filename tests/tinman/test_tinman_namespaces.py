"""Two TinMans on one ROS domain under two namespaces (issue 30 item 2): each run's ROS topics are
its own (/r1/cmd_vel, /r2/cmd_vel: what a ROS tool on the domain sees), and both complete."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from anodize._tools import cli

REPO = Path(__file__).resolve().parents[2]
RUN_LIMIT = 240.0  # seconds each run may take in all (starting processes and DDS discovery on a busy machine)


class PublishedTopics:
    """Every topic a DDS writer on ``domain`` publishes, as DDS discovery announces it (what
    ``ros2 topic list`` reads), collected on a thread until :meth:`stop`."""

    def __init__(self, domain: int) -> None:
        from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
        from cyclonedds.domain import DomainParticipant

        self.participant = DomainParticipant(domain)
        self.reader = BuiltinDataReader(self.participant, BuiltinTopicDcpsPublication)
        self.names: set[str] = set()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._collect, name="published-topics", daemon=True)
        self._thread.start()

    def _collect(self) -> None:
        while not self._stop.wait(0.1):
            self.names.update(sample.topic_name for sample in self.reader.take(N=256) if sample.topic_name)

    def stop(self) -> set[str]:
        self._stop.set()
        self._thread.join(timeout=5)
        return self.names


def _tinman(namespace: str, out: Path, sequence: Path, env: dict[str, str], *options: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "anodize._tools.cli", "run", "tinman", "--quiet", "--transport", "dds",
         "--namespace", namespace, "--duration", "4", "--dataset", str(sequence), "--out", str(out), *options],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


@pytest.mark.slow
def test_two_tinmans_in_one_domain_under_two_namespaces_do_not_meet(tmp_path: Path, tinman_sequence: Path) -> None:
    domain = 1 + (os.getpid() + 101) % 200  # the domain of this test alone (never 0, where real ROS nodes may be)
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "TINMAN_SETTINGS": "",
           "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tinman" / "src"), os.environ.get("PYTHONPATH", "")])}
    watcher = PublishedTopics(domain)
    try:
        runs = {ns: _tinman(f"/{ns}", tmp_path / ns, tinman_sequence, env,
                            *(["-p", "Move.max_speed=0.3"] if ns == "r2" else [])) for ns in ("r1", "r2")}
        outputs = {ns: run.communicate(timeout=RUN_LIMIT)[0] for ns, run in runs.items()}
    finally:
        topics = watcher.stop()
    reports = {ns: json.loads((tmp_path / ns / "report.json").read_text()) for ns in runs}
    for ns, report in reports.items():
        # Both ran to their end and drove (the mission's messages flowed both ways). Two robots on a shared
        # two-core machine may miss the control loop's deadlines (a DeadlineMissedError, with the peers'
        # PeerFailedError after it): that is load, not the runs meeting; any other violation or failure is not.
        assert runs[ns].returncode in (0, 1) and report["transport"] == "dds", (ns, outputs[ns][-3000:])
        assert report["messages"]["Move->Gazebo"] > 0, (ns, report["messages"])
        failures = {role: r["error"] for role, r in report["roles"].items() if r["error"] is not None}
        unexplained = {role: error for role, error in failures.items() if not _load(error)}
        assert unexplained == {}, (ns, report["problems"], outputs[ns][-3000:])
    ros_topics = {name for name in topics if name.startswith("rt/")}
    for ns in ("r1", "r2"):
        # The channels between groups (inside a group, /joy and the camera's images are no DDS topics).
        assert {f"rt/{ns}/cmd_vel", f"rt/{ns}/odom", f"rt/{ns}/plan"} <= ros_topics, ros_topics
    assert "rt/cmd_vel" not in ros_topics and "rt/odom" not in ros_topics  # nothing left un-namespaced
    # Every topic is under a robot's namespace but /rosout, which is global in ROS 2 too: both robots' logs.
    assert {name.split("/")[1] for name in ros_topics} == {"r1", "r2", "rosout"}, ros_topics
    # Each run's own DDS traffic (its internal channels) is named by its run id: the namespace is in it.
    assert "DDS domain" in outputs["r1"] and "run TinManParallel.r1" in outputs["r1"], outputs["r1"][-2000:]
    assert "run TinManParallel.r2" in outputs["r2"]


def _load(error: dict[str, str]) -> bool:
    """A role's failure a busy machine explains: a missed deadline, the peers' loss of the role that missed it."""
    return error["type"] in ("DeadlineMissedError", "PeerFailedError")


@pytest.mark.parametrize(("override", "message"), [
    ("Move.max_speed=\"fast\"", 'error: command line: -p Move.max_speed: expected float, got str ("fast")'),
    ("Move.top_speed=0.3", ("error: command line: -p Move.top_speed: move takes no such parameter; its parameters: "
                           "max_speed")),
    ("Mover.max_speed=0.3", "error: command line: -p Mover.max_speed: no role Mover runs in a group of "),
])
def test_a_bad_parameter_of_tinman_is_a_usage_error(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
                                                    tmp_path: Path, override: str, message: str) -> None:
    monkeypatch.setenv("TINMAN_SETTINGS", "")
    assert cli.main(["run", "tinman", "--quiet", "--out", str(tmp_path), "-p", override]) == 2
    err = capsys.readouterr().err
    assert err.startswith(message) and "Traceback" not in err, err
    assert not (tmp_path / "report.json").exists()
