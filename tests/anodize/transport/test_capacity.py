"""Honest channels: every report gives each channel's high-water mark (the most messages that
waited in it), and a channel given a capacity makes its sender wait while it is full, on every
transport where a channel is counted in messages: threads of one process, groups' own queues, DDS."""

from __future__ import annotations

import capacity_roles as roles
import pytest
from dds_hosts import domain

import anodize
import sessiontypes
from anodize import ConfigurationError, PeerFailedError, RoleStopped, Transport
from anodize._supervision.report import RoleStatus

STREAM = sessiontypes.loads(roles.STREAM, "stream.proto").globals["Stream"]


def stream(transport: Transport | None = None, capacities: dict[str, int] | None = None, same_group: bool = True,
           consumer: object = roles.slow_consumer) -> anodize.System:
    system = anodize.System(STREAM, transport=transport or anodize.Inproc(), capacities=capacities)
    if same_group:
        system.group("both").role("P", roles.eager_producer).role("C", consumer)
    else:
        system.group("producing").role("P", roles.eager_producer)
        system.group("consuming").role("C", consumer)
    return system


def test_an_unbounded_channel_reports_how_far_its_receiver_fell_behind() -> None:
    report = stream().run(timeout=30)
    assert report.ok, report.summary()
    assert report.high_water["P->C"] > 100  # the producer ran ahead by most of its 200
    assert report.capacities == {} and f"most messages waiting: P->C {report.high_water['P->C']}" in report.summary()


@pytest.mark.parametrize("transport", [pytest.param(anodize.Inproc(), id="inproc"),
                                       pytest.param(anodize.Processes(), id="process", marks=pytest.mark.slow)])
def test_a_capacity_holds_the_sender_back(transport: Transport) -> None:
    report = stream(transport, {"P->C": 3}).run(timeout=30)
    assert report.ok, report.summary()
    assert 1 <= report.high_water["P->C"] <= 3, report.high_water
    assert report.capacities == {"P->C": 3} and "P->C" in report.summary() and " of 3" in report.summary()


@pytest.mark.slow
def test_a_capacity_narrows_the_dds_credit_window() -> None:
    carrier = anodize.Dds(domain=domain(), run_id="capacity", wait=20)
    report = stream(carrier, {"P->C": 5}, same_group=False).run(timeout=60)
    assert report.ok, report.summary()
    # Counted from the receiver's credits: at most the capacity (plus the message being sent).
    assert 1 <= report.high_water["P->C"] <= 5, report.high_water


def test_a_sender_waiting_on_a_full_channel_is_stopped_by_the_timeout() -> None:
    report = stream(anodize.Inproc(), {"P->C": 2}, consumer=roles.stuck_consumer).run(timeout=1.0)
    producer = report.roles["P"]
    assert producer.status is RoleStatus.STOPPED, report.summary()
    assert isinstance(producer.error, RoleStopped) or producer.error is None
    assert report.high_water["P->C"] == 2


def test_a_sender_waiting_on_a_full_channel_hears_that_its_receiver_failed() -> None:
    report = stream(anodize.Inproc(), {"P->C": 2}, consumer=roles.failing_consumer).run(timeout=30)
    assert isinstance(report.roles["P"].error, PeerFailedError), report.summary()
    assert "the consumer gives up" in str(report.roles["P"].error)


def test_capacities_are_checked_against_the_protocol() -> None:
    with pytest.raises(ConfigurationError, match="global Stream has no channel C->P; its channels are P->C"):
        stream(anodize.Inproc(), {"C->P": 2})
    with pytest.raises(ConfigurationError, match="expected a whole number of messages >= 1, got 0"):
        stream(anodize.Inproc(), {"P->C": 0})


@pytest.mark.parametrize("capacities", [None, {"P->C": 2}])
def test_a_receiver_waiting_on_its_groups_own_channel_is_stopped_by_the_timeout(
        capacities: dict[str, int] | None) -> None:
    system = anodize.System(STREAM, transport=anodize.Processes(), capacities=capacities)
    system.group("both").role("P", "capacity_roles:silent_producer").role("C", "capacity_roles:waiting_consumer")
    report = system.run(timeout=1.0, grace=5.0)
    consumer = report.roles["C"]
    assert consumer.status is RoleStatus.STOPPED, report.summary()
    # Woken by the stop, not killed with its group after the grace period ("its process ended").
    assert "waiting at the head of its loop (state 0) for ?P" in report.summary(), report.summary()
