"""The supervisors' words over Zenoh (ZenohHostLink): two in-process peer sessions on loopback,
scouting off. What one says, the other hears, in order, from the host and supervisor that said
it; a word from another run's claim or from a host outside the system is dropped, noted once."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator

import pytest

from anodize._supervision.words import Decision, HelloWord, RestartWord, StopWord, Word

zenoh = pytest.importorskip("zenoh", reason="the zenoh extra is not installed")

from anodize._supervision.zenohlink import ZenohHostLink  # noqa: E402  (needs zenoh)

PREFIX = "anodize/hoststest/digest"
CLAIM = "hoststest/sEcReTtOkEn"
HOSTS = ("A", "B")


def free_endpoint() -> str:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"


PING = "ping"  # what meet() says until it is heard


def peer(listen: str | None = None, connect: str | None = None) -> zenoh.Session:
    config = {"mode": "peer", "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
              "listen": {"endpoints": [listen] if listen else []},
              "connect": {"endpoints": [connect] if connect else []}}
    return zenoh.open(zenoh.Config.from_json5(json.dumps(config)))


@pytest.fixture(scope="module")
def sessions() -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    endpoint = free_endpoint()
    a = peer(listen=endpoint)
    b = peer(connect=endpoint)
    yield a, b
    b.close()
    a.close()


def spoken(link: ZenohHostLink) -> list[Word]:
    """The words ``link`` heard since last asked, but :func:`meet`'s pings (one may come late)."""
    return [w for w in link.words() if not (isinstance(w, StopWord) and w.why == PING)]


def heard(link: ZenohHostLink, count: int, seconds: float = 10.0) -> list[Word]:
    """The next ``count`` words ``link`` hears (bounded), but pings."""
    words: list[Word] = []
    deadline = time.monotonic() + seconds
    while len(words) < count and time.monotonic() < deadline:
        words += spoken(link)
        time.sleep(0.01)
    return words


def meet(speaker: ZenohHostLink, listener: ZenohHostLink) -> None:
    """Until the listener hears the speaker (a put before the subscriber is matched is lost)."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        speaker.say(StopWord(speaker.host, PING))
        time.sleep(0.05)
        if listener.words():
            return
    raise AssertionError("the two sessions never met")


def test_words_arrive_in_order_from_the_host_and_supervisor_that_said_them(
        sessions: tuple[zenoh.Session, zenoh.Session]) -> None:
    a = ZenohHostLink(sessions[0], PREFIX + "1", CLAIM, "A", HOSTS)
    b = ZenohHostLink(sessions[1], PREFIX + "1", CLAIM, "B", HOSTS)
    try:
        meet(a, b)
        said: list[Word] = [RestartWord("A", ("p", "c"), 1, "role P failed"),
                            HelloWord("A", 7, {"p": 1}, restarts=(Decision(1, ("p", "c"), "why", "A"),)),
                            *[StopWord("A", f"stop {i}") for i in range(200)]]
        for word in said:
            a.say(word)
        words = heard(b, len(said))
        assert words == [type(w)(**{**w.__dict__, "supervisor": a.supervisor}) for w in said]  # type: ignore[arg-type]
        assert b.batches == {1: frozenset({"p", "c"})}
        assert a.words() == [] and a.notes == [] and b.notes == []  # its own words are not heard back
    finally:
        a.close()
        b.close()


def test_words_from_another_claim_or_host_are_dropped_and_noted_once(
        sessions: tuple[zenoh.Session, zenoh.Session]) -> None:
    listener = ZenohHostLink(sessions[1], PREFIX + "2", CLAIM, "B", HOSTS)
    honest = ZenohHostLink(sessions[0], PREFIX + "2", CLAIM, "A", HOSTS)
    forger = ZenohHostLink(sessions[0], PREFIX + "2", "hoststest/guessed", "A", HOSTS)
    stranger = ZenohHostLink(sessions[0], PREFIX + "2", CLAIM, "moon", ("moon", "B"))
    try:
        meet(honest, listener)
        for _ in range(3):
            forger.say(StopWord("A", "forged"))
            stranger.say(StopWord("moon", "not of the system"))
        honest.say(StopWord("A", "last"))
        words = heard(listener, 1)
        time.sleep(0.2)
        words += spoken(listener)
        assert words == [StopWord("A", "last", honest.supervisor)]
        assert sorted(listener.notes) == sorted([
            (f"rejected supervisor words on Zenoh from 'anodize-supervisor2;A;{forger.supervisor}' (it does not "
            "prove it knows the run's claim); only the run's hosts may speak there"),
            (f"rejected supervisor words on Zenoh from 'anodize-supervisor2;moon;{stranger.supervisor}' (it is not "
            "one of the system's hosts); only the run's hosts may speak there")])
    finally:
        for link in (listener, honest, forger, stranger):
            link.close()
