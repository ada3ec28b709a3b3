"""Role functions for the replay tests (module level: a recording names them, replay imports them).

Two-buyer roles (protocols/two_buyer.proto), plus a seller that quotes another price, a
seller that breaks the protocol, a buyer that paces itself with ``Endpoint.sleep`` and a
buyer that never stops, for the replays that must not pass or must end on their own.
"""

from __future__ import annotations

import math

from anodize import Endpoint

PRICES = {"Ulysses": 140, "War and Peace": 60}
TITLE = "Ulysses"


def buyer1(ep: Endpoint) -> None:
    ep.send("S", "title", TITLE)
    quote = ep.recv("S").payload
    ep.send("B2", "share", quote // 2)


def buyer2(ep: Endpoint) -> None:
    quote = ep.recv("S").payload
    share = ep.recv("B1").payload
    if quote - share > 100:
        ep.send("S", "quit")
        return
    ep.send("S", "ok", "1 Wonderland Road")
    ep.recv("S")


def seller(ep: Endpoint) -> None:
    title = ep.recv("B1").payload
    price = PRICES.get(title, 99)
    ep.send("B1", "quote", price)
    ep.send("B2", "quote", price)
    if ep.recv("B2").label == "ok":
        ep.send("B2", "date", "2026-12-01")


def seller_on_sale(ep: Endpoint) -> None:
    """Quotes 10% less to buyer 2 than the recorded seller did."""
    title = ep.recv("B1").payload
    price = PRICES.get(title, 99)
    ep.send("B1", "quote", price)
    ep.send("B2", "quote", price * 9 // 10)
    if ep.recv("B2").label == "ok":
        ep.send("B2", "date", "2026-12-01")


def seller_skipping_buyer2(ep: Endpoint) -> None:
    """Breaks the protocol: waits for buyer 2's answer before quoting to it."""
    title = ep.recv("B1").payload
    ep.send("B1", "quote", PRICES.get(title, 99))
    ep.recv("B2")


def seller_done_early(ep: Endpoint) -> None:
    """Sends to buyer 1 as recorded, then returns without quoting to buyer 2."""
    title = ep.recv("B1").payload
    ep.send("B1", "quote", PRICES.get(title, 99))


def patient_buyer1(ep: Endpoint) -> None:
    """Buyer 1 thinking it over for an hour before each message."""
    ep.sleep(3600.0)
    ep.send("S", "title", TITLE)
    quote = ep.recv("S").payload
    ep.sleep(3600.0)
    ep.send("B2", "share", quote // 2)


def crashing_buyer1(ep: Endpoint) -> None:
    """Fails on the recorded quote, as it did on the robot."""
    ep.send("S", "title", TITLE)
    quote = ep.recv("S").payload
    if quote > 100:
        raise ValueError(f"quote {quote} is out of range")
    ep.send("B2", "share", quote // 2)


def idle_buyer1(ep: Endpoint) -> None:
    """Idles until the run stops, once it has done its part."""
    buyer1(ep)
    ep.sleep(math.inf)


def sleepy_buyer1(ep: Endpoint) -> None:
    """Sleeps until the run stops before sending its share, which the recorded buyer 1 did send."""
    ep.send("S", "title", TITLE)
    ep.recv("S")
    ep.sleep(math.inf)
