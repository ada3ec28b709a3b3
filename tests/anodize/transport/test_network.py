"""A group's network composed from a transport's links: what it asks of them and when.

A recording fake transport stands in for pipes or DDS: the network must build its
channels from the links, silence a failed receiver's links, wake them on stop, tell them
of remote failures, bridge them for roles that wait on several, and close them.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping
from queue import SimpleQueue

from anodize._session.channel import STOP, Channel, PeerFailure
from anodize._transport.bridge import BridgeQueue
from anodize._transport.codec import Codec
from anodize._transport.inproc import BoundedQueue
from anodize._transport.links import LinkNetwork
from anodize._transport.network import GroupNetwork


class FakeEnd(SimpleQueue):  # type: ignore[type-arg]
    frame_size = 1


class FakeLinks:
    """Every cross-group pair is a queue; each call is written down."""

    def __init__(self) -> None:
        self.calls: list[tuple[object, ...]] = []
        self.ends: dict[tuple[str, str], FakeEnd] = {}

    def pairs(self, local_roles: Collection[str], channels: Iterable[tuple[str, str]],
              dead: Mapping[str, str]) -> list[tuple[str, str]]:
        return [(a, b) for a, b in channels if (a in local_roles) != (b in local_roles) and a not in dead]

    def writer(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> Channel:
        self.calls.append(("writer", pair))
        return self.ends.setdefault(pair, FakeEnd())

    def reader(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> Channel:
        self.calls.append(("reader", pair))
        return self.ends.setdefault(pair, FakeEnd())

    def silence(self, pair: tuple[str, str]) -> None:
        self.calls.append(("silence", pair))

    def noted_failed(self, role: str) -> None:
        self.calls.append(("noted_failed", role))

    def wake(self) -> None:
        self.calls.append(("wake",))

    def close(self, linger: float) -> None:
        self.calls.append(("close", linger))


CHANNELS = [("A", "B"), ("B", "A"), ("A", "C"), ("C", "A"), ("B", "C"), ("D", "A")]


def _network(links: FakeLinks, doorbells: tuple[str, ...] = ()) -> GroupNetwork:
    return GroupNetwork(["A", "B"], CHANNELS, links, {"D": "its group did not start"}, lambda pair: Codec(),
                        doorbells, capacities={("A", "B"): 3})


def test_local_pairs_are_queues_and_every_cross_group_pair_is_a_link() -> None:
    links = FakeLinks()
    network = _network(links)
    assert links.calls == [("writer", ("A", "C")), ("reader", ("C", "A")), ("writer", ("B", "C"))]
    assert isinstance(network.queues[("A", "B")], BoundedQueue)  # its capacity
    assert type(network.queues[("B", "A")]) is SimpleQueue
    assert network.queues[("C", "A")] is links.ends[("C", "A")]
    gone = network.queues[("D", "A")]  # a dead peer: its failure waits for the receiver
    assert gone.get() == PeerFailure("D", "its group did not start")
    assert network.failed == {"D": "its group did not start"} and network.alarm


def test_a_local_failure_silences_its_links_and_is_written_after_what_was_sent() -> None:
    links = FakeLinks()
    network = _network(links)
    network.queues[("A", "C")].put(("x", 1))
    network.fail("A", "boom")
    assert links.calls[3:] == [("silence", ("C", "A"))]
    assert [links.ends[("A", "C")].get(), links.ends[("A", "C")].get()] == [("x", 1), PeerFailure("A", "boom")]
    assert network.queues[("A", "B")].get() == PeerFailure("A", "boom")


def test_a_remote_failure_is_noted_and_the_links_told_and_a_stop_wakes_them() -> None:
    links = FakeLinks()
    network = _network(links)
    network.fail("C", "gone")
    assert network.failed["C"] == "gone" and links.calls[-1] == ("noted_failed", "C")
    assert network.wait_for_cause("C", "unknown") == "gone"
    event = network.stop_event_for("B")
    network.stop()
    assert event.is_set() and network.stopping and links.calls[-1] == ("wake",)
    assert network.queues[("B", "A")].get() == STOP
    network.close(0.5)
    assert links.calls[-1] == ("close", 0.5)


def test_a_role_waiting_on_several_channels_gets_its_links_bridged() -> None:
    links = FakeLinks()
    network = _network(links, doorbells=("A",))
    bridged = network.queues[("C", "A")]
    assert isinstance(bridged, BridgeQueue) and len(network.bridges) == 1
    network.start()
    links.ends[("C", "A")].put(("hello", 1))
    assert bridged.get(timeout=10) == ("hello", 1)
    assert network.doorbells["A"].get(timeout=10) == "C"
