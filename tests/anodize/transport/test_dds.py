"""Dds on one host (loopback): the protocol runs, nothing is lost, duplicated or
reordered, a killed peer is reported, a forged writer is rejected. The same across two network
namespaces, over a lossy link, is in test_dds_hosts.py."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import dds_roles
import pytest
from dds_hosts import domain, finish, start_host, wait_for_group, wait_until_flowing, write_system

import anodize
import sessiontypes
from anodize import PeerFailedError
from anodize._supervision.report import RoleStatus

STREAM = sessiontypes.loads(dds_roles.STREAM, "stream.proto").globals["Stream"]
REPO = Path(__file__).resolve().parents[3]


def stream_system(producer: object, consumer: object, run_id: str, host: str | None = None) -> anodize.System:
    system = anodize.System(STREAM, transport=anodize.Dds(domain=domain(), run_id=run_id, host=host, wait=20))
    system.group("producing").role("P", producer)
    system.group("consuming").role("C", consumer)
    return system


def test_a_protocol_with_choices_and_recursion_completes(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "2000")
    report = stream_system(dds_roles.producer, dds_roles.consumer, "choices").run(timeout=60)
    assert report.ok, report.summary()
    assert report.groups["consuming"].received == 2001


@pytest.mark.slow  # DDS groups in processes for seconds
def test_the_two_hosts_example_runs_here_with_both_groups() -> None:
    result = subprocess.run([sys.executable, "-m", "anodize._tools.cli", "run", "--quiet", "--timeout", "60",
                             str(REPO / "examples/two_hosts/two_hosts.toml")],
                            capture_output=True, text=True, timeout=120,
                            env={**os.environ, "ANODIZE_DDS_DOMAIN": str(domain())})
    assert result.returncode == 0, result.stdout + result.stderr
    assert "protocol Teleop: ok" in result.stdout


@pytest.mark.slow  # DDS groups in processes for seconds
def test_a_slow_receiver_holds_the_sender_back(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "1000")
    progress = tmp_path / "consumed"
    progress.write_text("0")
    monkeypatch.setenv("DDS_TEST_PROGRESS", str(progress))
    report = stream_system(dds_roles.eager_producer, dds_roles.slow_consumer, "backpressure").run(timeout=60)
    assert report.ok, report.summary()
    # The sender is at most the credit window (224) ahead of what the consumer has had:
    # memory stays bounded (without flow control it ran ahead by all 1000).
    ahead = int((tmp_path / "consumed.ahead").read_text())
    assert ahead <= 224 + 1, ahead


@pytest.mark.slow  # DDS groups in processes for seconds
def test_a_slow_receiver_of_frames_holds_the_sender_to_a_few_megabytes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "200")
    monkeypatch.setenv("DDS_TEST_FRAMES", "1")
    progress = tmp_path / "consumed"
    progress.write_text("0")
    monkeypatch.setenv("DDS_TEST_PROGRESS", str(progress))
    report = stream_system(dds_roles.eager_producer, dds_roles.slow_consumer, "backpressure_frames").run(timeout=60)
    assert report.ok, report.summary()
    # Frames of 900 KiB: the byte window (16 MiB, ~18 frames) binds long before the sample
    # window (224) does; it covers what the receiver has taken but not handed on too.
    ahead = int((tmp_path / "consumed.ahead").read_text())
    assert ahead <= 16 * 2**20 // (480 * 640 * 3) + 2, ahead


@pytest.mark.slow
def test_100000_messages_and_1000_frames_cross_in_order(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "100000")
    report = stream_system(dds_roles.producer, dds_roles.consumer, "many").run(timeout=300)
    assert report.ok, report.summary()
    monkeypatch.setenv("DDS_TEST_COUNT", "1000")
    report = stream_system(dds_roles.frame_producer, dds_roles.frame_consumer, "frames").run(timeout=300)
    assert report.ok, report.summary()


def test_peers_that_never_appear_are_named_with_their_host() -> None:
    system = anodize.System(STREAM, transport=anodize.Dds(domain=domain(), run_id="lonely", host="robot", wait=1.0))
    system.group("producing", host="robot").role("P", dds_roles.producer)
    system.group("consuming", host="base").role("C", dds_roles.consumer)
    report = system.run(timeout=30)
    assert not report.ok
    error = str(report.groups["producing"].error)
    assert "no sign of group consuming on host base (for P->C)" in error, error
    assert any("groups running elsewhere: consuming on host base" in note for note in report.notes)
    # Over several hosts without a shared token, the report says what the run's isolation rests on.
    assert any("no ANODIZE_DDS_TOKEN: the run's DDS partition and claims rest on its run id alone" in note
               for note in report.notes), report.notes


def test_an_unknown_host_is_a_configuration_error() -> None:
    system = stream_system(dds_roles.producer, dds_roles.consumer, "x", host="moon")
    with pytest.raises(anodize.ConfigurationError, match="no group runs on host 'moon'"):
        system.run()


@pytest.mark.slow  # DDS groups in processes for seconds
def test_a_killed_host_is_reported_to_the_other_as_a_peer_failure(tmp_path: Path) -> None:
    system = write_system(tmp_path, "slow_producer", "killed")
    flowing = {"DDS_TEST_FLOWING": str(tmp_path / "flowing")}
    consumer = start_host(system, "B", tmp_path / "b.json", flowing)
    producer = start_host(system, "A", tmp_path / "a.json", flowing)
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
    report = json.loads((tmp_path / "b.json").read_text())
    role = report["roles"]["C"]
    assert role["status"] == RoleStatus.FAILED, out
    assert role["error"]["type"] == PeerFailedError.__name__, out
    assert "group producing on host A" in role["error"]["message"], out
    print(f"the kill was noticed after {noticed_after:.2f} s (lease 1 s)")


def test_a_thread_still_receiving_for_a_failed_role_is_stopped_and_its_sender_not_blamed(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The group deletes a failed role's readers (so their writers see them gone); a thread of the
    # role still in a receive then found its reader deleted, and the sender was blamed for a
    # sample "that could not be decoded" (TinMan's Move-estimates, beside two CPU hogs).
    outcome = tmp_path / "outcome"
    monkeypatch.setenv("DDS_TEST_OUTCOME", str(outcome))
    held = sessiontypes.loads(dds_roles.HELD, "held.proto").globals["Held"]
    system = anodize.System(held, transport=anodize.Dds(domain=domain(), run_id="held", wait=20))
    system.group("producing").role("P", dds_roles.held_producer)
    system.group("consuming").role("C", dds_roles.failing_with_a_receiving_thread).role(
        "K", dds_roles.keeping_the_group_alive)
    report = system.run(timeout=60)
    assert outcome.read_text() == "RoleStopped", report.summary()
    error = report.roles["C"].error
    assert error is not None and "RuntimeError: C fails on purpose" in str(error), report.summary()  # its own
    # K is told that C failed. P's one send may go out before its group hears of the failure (then
    # P ends done) or after (then it is told): either way nobody blames P.
    assert isinstance(report.roles["K"].error, PeerFailedError), report.summary()
    assert report.roles["P"].error is None or isinstance(report.roles["P"].error, PeerFailedError), report.summary()
    assert "protocol violation" not in report.summary(), report.summary()


FORGER = textwrap.dedent("""
    import sys, time
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.topic import Topic
    from cyclonedds.pub import DataWriter
    from cyclonedds.core import Qos, Policy
    from cyclonedds.util import duration
    from anodize._transport.dds import Frame, topic_name
    from anodize._transport.codec import Codec
    participant = DomainParticipant(int(sys.argv[1]))
    topic = Topic(participant, topic_name(sys.argv[2], "P", "C"), Frame)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepAll,
              Policy.Liveliness.Automatic(duration(seconds=1)), Policy.Userdata(b"anodize1;other;intruder;0;X;1"),
              Policy.Partition([sys.argv[3]]))
    writer = DataWriter(participant, topic, qos=qos)
    frame = Codec().message_frame("data", 10**9)
    for _ in range(200):
        writer.write(Frame(data=list(frame)))
        time.sleep(0.01)
""")


@pytest.mark.slow  # DDS groups in processes for seconds
def test_a_forged_writer_is_rejected_and_reported(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The forger knows the run's token (as one that read the discovery traffic of a run would),
    # so it meets the run's reader in the run's partition; it claims some other identity.
    monkeypatch.setenv("DDS_TEST_COUNT", "300")
    monkeypatch.setenv("ANODIZE_DDS_TOKEN", "known_to_the_forger")
    forger = subprocess.Popen([sys.executable, "-c", FORGER, str(domain()), "forged",
                               "anodize/forged/known_to_the_forger"])
    try:
        system = stream_system(dds_roles.slow_producer_of_count, dds_roles.consumer, "forged")
        report = system.run(timeout=60)
    finally:
        forger.kill()
        forger.wait()
    assert report.ok, report.summary()  # the consumer saw 0..299 in order: no forged sample got in
    note = "; ".join(report.groups["consuming"].notes)
    assert "rejected samples on P->C from DDS writer" in note, note
    assert "it claims 'anodize1;other;intruder;0;X;1'" in note, note


def test_with_a_host_given_every_group_needs_one() -> None:
    system = anodize.System(STREAM, transport=anodize.Dds(domain=domain(), run_id="half", host="robot"))
    system.group("producing", host="robot").role("P", dds_roles.producer)
    system.group("consuming").role("C", dds_roles.consumer)
    with pytest.raises(anodize.ConfigurationError, match="groups consuming have no host"):
        system.run()
