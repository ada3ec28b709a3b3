"""Zenoh on one host (loopback, an in-process router, scouting off): the protocol runs, nothing is
lost, duplicated or reordered, back pressure bounds memory, a forged writer is rejected, peer mode
works with endpoints given per host, and a router that restarts is ridden through. A killed host,
and the system file, are in test_zenoh_hosts.py."""

from __future__ import annotations

import json
import threading
import uuid
from collections.abc import Iterator
from pathlib import Path

import dds_roles
import pytest
from zenoh_hosts import free_endpoint, open_router

import anodize
import sessiontypes
from anodize._transport.zenoh import ZenohSettings

zenoh = pytest.importorskip("zenoh", reason="the zenoh extra is not installed")

STREAM = sessiontypes.loads(dds_roles.STREAM, "stream.proto").globals["Stream"]


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    """A Zenoh router in this process, on a loopback port of its own; its endpoint."""
    endpoint = free_endpoint()
    session = open_router(endpoint)
    yield endpoint
    session.close()


def run_id() -> str:
    """A run id of this test alone: runs of tests at once never share a key."""
    return "t" + uuid.uuid4().hex[:12]


def stream_system(router: str, producer: object, consumer: object, **fields: object) -> anodize.System:
    """P in one group, C in another, both clients of ``router``."""
    fields.setdefault("run_id", run_id())
    fields.setdefault("wait", 20.0)
    transport = anodize.Zenoh(mode="client", connect=(router,), scouting=False, **fields)  # type: ignore[arg-type]
    system = anodize.System(STREAM, transport=transport)
    system.group("producing").role("P", producer)
    system.group("consuming").role("C", consumer)
    return system


def test_a_protocol_with_choices_and_recursion_completes(router: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "2000")
    report = stream_system(router, dds_roles.producer, dds_roles.consumer).run(timeout=60)
    assert report.ok, report.summary()
    assert report.groups["consuming"].received == 2001
    assert any("Zenoh client mode (connect " + router in note for note in report.notes), report.notes


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_a_role_failing_in_a_live_process_is_told_to_its_peer_after_its_last_message(router: str) -> None:
    report = stream_system(router, dds_roles.failing_producer, dds_roles.consumer).run(timeout=60)
    consumer = report.roles["C"]
    assert consumer.status.name == "FAILED", report.summary()
    assert "the producer gives up" in str(consumer.error), report.summary()  # the failure frame's cause
    assert report.groups["consuming"].received == 5  # every number sent before the failure


def test_peer_mode_with_the_endpoints_of_each_host(monkeypatch: pytest.MonkeyPatch) -> None:
    # Every group runs here (no --host), each with its own host's endpoints: A listens, B connects.
    monkeypatch.setenv("DDS_TEST_COUNT", "500")
    endpoint = free_endpoint()
    transport = anodize.Zenoh(mode="peer", scouting=False, run_id=run_id(), wait=20,
                              hosts=(("A", "peer", (), (endpoint,)), ("B", "peer", (endpoint,), ())))
    system = anodize.System(STREAM, transport=transport)
    system.group("producing", host="A").role("P", dds_roles.producer)
    system.group("consuming", host="B").role("C", dds_roles.consumer)
    report = system.run(timeout=60)
    assert report.ok, report.summary()
    assert any(f"host B: Zenoh peer mode, connect {endpoint}" in note for note in report.notes), report.notes


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_100000_messages_and_1000_frames_cross_in_order(router: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "100000")
    report = stream_system(router, dds_roles.producer, dds_roles.consumer).run(timeout=300)
    assert report.ok, report.summary()
    monkeypatch.setenv("DDS_TEST_COUNT", "1000")
    report = stream_system(router, dds_roles.frame_producer, dds_roles.frame_consumer).run(timeout=300)
    assert report.ok, report.summary()


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_a_slow_receiver_holds_the_sender_back(router: str, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "1000")
    progress = tmp_path / "consumed"
    progress.write_text("0")
    monkeypatch.setenv("DDS_TEST_PROGRESS", str(progress))
    report = stream_system(router, dds_roles.eager_producer, dds_roles.slow_consumer).run(timeout=60)
    assert report.ok, report.summary()
    # At most the credit window (224) ahead of what the consumer has had (without credits: all 1000).
    ahead = int((tmp_path / "consumed.ahead").read_text())
    assert ahead <= 224 + 1, ahead
    # Frames of 900 KiB: the byte window (16 MiB, ~18 frames) binds first.
    monkeypatch.setenv("DDS_TEST_COUNT", "100")
    monkeypatch.setenv("DDS_TEST_FRAMES", "1")
    progress.write_text("0")
    report = stream_system(router, dds_roles.eager_producer, dds_roles.slow_consumer).run(timeout=60)
    assert report.ok, report.summary()
    ahead = int((tmp_path / "consumed.ahead").read_text())
    assert ahead <= 16 * 2**20 // (480 * 640 * 3) + 2, ahead


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_a_forged_writer_is_rejected_and_named(router: str, monkeypatch: pytest.MonkeyPatch) -> None:
    # The forger knows the run's token (as one that read the run's traffic would), so it puts on
    # the channel's very key, with numbers the receiver expects; it claims another identity.
    monkeypatch.setenv("DDS_TEST_COUNT", "300")
    monkeypatch.setenv("ANODIZE_ZENOH_TOKEN", "known_to_the_forger")
    run = run_id()
    key = ZenohSettings(mode="client", run_id=run, host="", group_of={}, host_of={},
                        token="known_to_the_forger").channel_key("P", "C")
    forger = zenoh.open(zenoh.Config.from_json5(json.dumps(
        {"mode": "client", "connect": {"endpoints": [router]}, "scouting": {"multicast": {"enabled": False}}})))
    done = threading.Event()
    frame = anodize._transport.codec.Codec().message_frame("data", 10**9)

    def forge() -> None:
        number = 0
        while not done.wait(0.005):
            forger.put(key, frame, attachment=number.to_bytes(8, "little") + b"\x01" * 8 + b"anodize1;intruder")
            number += 1

    thread = threading.Thread(target=forge, daemon=True)
    thread.start()
    try:
        report = stream_system(router, dds_roles.slow_producer_of_count, dds_roles.consumer, run_id=run).run(timeout=60)
    finally:
        done.set()
        thread.join(5)
        forger.close()
    assert report.ok, report.summary()  # the consumer saw 0..299 in order: no forged sample got in
    note = "; ".join(report.groups["consuming"].notes)
    assert "rejected samples on P->C from Zenoh writer 0101010101010101 (it claims 'anodize1;intruder')" in note, note
    assert "(group producing on host" in note, note  # the honest writer is the one that may write
    assert "P" not in {r for r, role in report.roles.items() if role.status.name == "FAILED"}


@pytest.mark.slow  # a router restarted under a run
def test_a_router_that_restarts_is_ridden_through(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "1000")
    monkeypatch.setenv("ANODIZE_ZENOH_TOKEN", "known_to_the_test")
    run = run_id()
    credits = ZenohSettings(mode="client", run_id=run, host="", group_of={}, host_of={},
                            token="known_to_the_test").credit_key("P", "C")
    endpoint = free_endpoint()
    holder = [open_router(endpoint)]
    flowing = threading.Event()  # the router itself sees the consumer's first credits: the run is under way
    holder[0].declare_subscriber(credits, lambda sample: flowing.set())
    restarted = threading.Event()

    def restart() -> None:  # mid-run: the router goes (with what it held), and comes back 1 s later
        if flowing.wait(60):
            holder[0].close()
            threading.Event().wait(1.0)
            holder[0] = open_router(endpoint)
            restarted.set()

    thread = threading.Thread(target=restart, daemon=True)
    thread.start()
    try:
        report = stream_system(endpoint, dds_roles.slow_producer_of_count, dds_roles.consumer, run_id=run,
                               outage=10.0).run(timeout=120)
    finally:
        thread.join(70)
        holder[0].close()
    assert restarted.is_set()
    assert report.ok, report.summary()  # 0..999 in order, though the router lost what it held
    notes = "; ".join(report.groups["producing"].notes)
    assert "samples sent again" in notes, notes  # what the router lost was sent again


@pytest.mark.slow  # a router that stays away
def test_a_router_that_stays_away_fails_the_run_within_its_outage(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "100000")
    monkeypatch.setenv("ANODIZE_ZENOH_TOKEN", "known_to_the_test")
    run = run_id()
    credits = ZenohSettings(mode="client", run_id=run, host="", group_of={}, host_of={},
                            token="known_to_the_test").credit_key("P", "C")
    endpoint = free_endpoint()
    router = open_router(endpoint)
    flowing = threading.Event()  # the router sees the consumer's first credits: the run is under way
    router.declare_subscriber(credits, lambda sample: flowing.set())
    system = stream_system(endpoint, dds_roles.slow_producer_of_count, dds_roles.consumer, run_id=run, outage=1.0)

    def go_away() -> None:  # mid-run, however long the groups took to start, and for good
        if flowing.wait(60):
            router.close()

    thread = threading.Thread(target=go_away, daemon=True)
    thread.start()
    try:
        report = system.run(timeout=120)  # bounded: a hang fails here
    finally:
        flowing.set()
        thread.join(10)
        router.close()
    assert not report.ok
    errors = " ".join(str(role.error) for role in report.roles.values())
    assert "cut off for over 2 s" in errors or "no sign of" in errors, report.summary()


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_a_client_whose_router_never_answers_fails_within_the_wait_naming_it() -> None:
    nowhere = free_endpoint()  # nothing listens there
    report = stream_system(nowhere, dds_roles.producer, dds_roles.consumer, wait=2.0).run(timeout=60)
    assert not report.ok
    error = str(report.groups["producing"].error)
    expected = (f"cannot open a Zenoh session in client mode (connect {nowhere}; listen default): no router "
                "answered within the wait (2 s from the group's start)")
    assert expected in error, report.summary()
