"""Dds runs are isolated from other runs and from early forgers (issue 27, item 2): a stray reader of
another run that never takes its samples does not hold a channel back; a forger that claims a
group before the run starts never wins the start barrier, its samples are never delivered, and the
honest sender is never blamed; a reader that subscribes to every partition and stalls a channel is
named in the report. Each stranger is a second DDS participant, in its own process
(tests/anodize/dds_strangers.py); every wait is bounded and the tests count messages, not time."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import dds_roles
import pytest
from dds_hosts import domain, finish, start_host, write_system

import anodize
import sessiontypes
from anodize._supervision.report import RoleStatus

STREAM = sessiontypes.loads(dds_roles.STREAM, "stream.proto").globals["Stream"]
STRANGERS = Path(__file__).resolve().parents[1] / "dds_strangers.py"


@contextmanager
def stranger(mode: str, run_id: str, tmp_path: Path) -> Iterator[None]:
    """The stranger of ``mode`` on this test's domain, there before the run starts."""
    ready = tmp_path / f"{mode}.ready"
    process = subprocess.Popen([sys.executable, str(STRANGERS), mode, str(domain()), run_id, str(ready)])
    try:
        deadline = time.monotonic() + 30
        while not ready.exists():
            assert process.poll() is None, f"the {mode} stranger ended with {process.returncode}"
            assert time.monotonic() < deadline, f"the {mode} stranger did not start in 30 s"
            time.sleep(0.05)
        time.sleep(0.5)  # its endpoints are announced on the domain before our groups join it
        yield
    finally:
        process.kill()
        process.wait()


def stream_system(producer: Callable[..., Any], consumer: Callable[..., Any], run_id: str) -> anodize.System:
    system = anodize.System(STREAM, transport=anodize.Dds(domain=domain(), run_id=run_id, wait=20))
    system.group("producing").role("P", producer)
    system.group("consuming").role("C", consumer)
    return system


@pytest.mark.slow  # DDS groups in processes for seconds
def test_a_stray_reader_of_another_run_does_not_hold_a_channel_back(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Before the fix the stray readers matched the channel's writer and, never taking, held
    # every write back: 224 of the 3000 messages crossed within the run's 30 s (all cross in well
    # under a second alone), and the sender's group failed at the end with an AttributeError.
    monkeypatch.setenv("DDS_TEST_COUNT", "3000")
    with stranger("stray", "isolated", tmp_path):
        report = stream_system(dds_roles.producer, dds_roles.consumer, "isolated").run(timeout=30)
    assert report.ok, report.summary()
    assert report.groups["consuming"].received == 3001, report.summary()
    notes = "; ".join((*report.groups["producing"].notes, *report.groups["consuming"].notes))
    assert "another_run" not in notes, notes  # never matched: nothing to reject or name


@pytest.mark.slow  # DDS groups in processes for seconds
def test_a_forger_that_claims_the_groups_before_the_run_never_wins(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Before the fix the forger, there first, was accepted at the start barrier (its garbage
    # reached C and P was blamed) or claimed alongside the honest group (the run did not start).
    monkeypatch.setenv("DDS_TEST_COUNT", "300")
    with stranger("forger", "claimed", tmp_path):
        report = stream_system(dds_roles.slow_producer_of_count, dds_roles.consumer, "claimed").run(timeout=60)
    assert report.ok, report.summary()  # C saw exactly 0..299 in order: no forged sample got in
    assert report.groups["consuming"].received == 301, report.summary()
    assert report.roles["P"].status == RoleStatus.DONE, report.summary()  # the honest sender is not blamed


@pytest.mark.slow  # DDS groups in processes for seconds
def test_a_reader_of_every_partition_that_holds_a_channel_back_is_named(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # A reader subscribed to every partition is one of this run's as far as DDS is concerned:
    # it can hold the channel back, and the report says which reader that is.
    monkeypatch.setenv("DDS_TEST_COUNT", "1000")
    with stranger("wildcard", "watched", tmp_path):
        report = stream_system(dds_roles.producer, dds_roles.consumer, "watched").run(timeout=15)
    # Cyclone either holds the writes back all along (the run times out) or lets them through and
    # waits at the end for acknowledgements that never come: either way the reader is named.
    notes = "; ".join(report.groups["producing"].notes)
    assert ("P->C: writes held back for over 1 s in all, with DDS readers matched there besides the reader of "
            "group consuming" in notes or "P->C: what was written was not all acknowledged within 2 s of the end, "
            "with DDS readers matched there" in notes), report.summary()
    assert "it claims 'anodize1;a_recorder;spy;0;X;1'" in notes, notes
    # Before the fix the sender's group failed at the end with "AttributeError", from the
    # binding's wait_for_acks: the honest sender blamed.
    assert report.roles["P"].status != RoleStatus.FAILED, report.summary()


@pytest.mark.slow  # DDS groups in processes for seconds
def test_over_two_hosts_a_token_both_are_given_keeps_an_early_forger_out(tmp_path: Path) -> None:
    # Two `anodize run --host` processes share only what the user gives them: the run id, and
    # here the token. The forger knows the run id and claims both groups before either starts.
    system = write_system(tmp_path, "slow_producer_of_count", "claimed_hosts")
    env = {"ANODIZE_DDS_TOKEN": "given_to_both_hosts", "DDS_TEST_COUNT": "300"}
    with stranger("forger", "claimed_hosts", tmp_path):
        consumer = start_host(system, "B", tmp_path / "b.json", env)
        producer = start_host(system, "A", tmp_path / "a.json", env)
        try:
            outputs = [finish(producer, 90), finish(consumer, 90)]  # bounded: a hang fails here
        finally:
            for process in (producer, consumer):
                process.kill()
                process.wait()
    consuming = json.loads((tmp_path / "b.json").read_text())
    producing = json.loads((tmp_path / "a.json").read_text())
    assert consuming["roles"]["C"]["status"] == RoleStatus.DONE, outputs
    assert producing["roles"]["P"]["status"] == RoleStatus.DONE, outputs
    assert consuming["groups"]["consuming"]["received"] == 301, outputs
    assert not any("no ANODIZE_DDS_TOKEN" in note for note in consuming["notes"]), consuming["notes"]


def test_a_token_that_is_not_one_is_a_configuration_error_that_does_not_show_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ANODIZE_DDS_TOKEN", "secret;7")
    system = stream_system(dds_roles.producer, dds_roles.consumer, "tokens")
    with pytest.raises(anodize.ConfigurationError) as error:
        system.run(timeout=30)
    message = str(error.value)
    assert "ANODIZE_DDS_TOKEN: expected 8 to 128 letters, digits, '_', '.' or '-', got 8 characters" in message
    assert "secret" not in message
