"""Role functions for the named-payload tests (module level: group processes import them)."""

from __future__ import annotations

from payload_roles import Point

from anodize import Endpoint

QUOTE = {"price": 120, "where": Point(1, 2.5), "by": "Sam"}


def seller(ep: Endpoint) -> None:
    ep.send("A", "quote", dict(QUOTE))
    ep.send("B", "quote", dict(QUOTE))
    bid = ep.recv("A").payload
    if bid != {"price": 110, "note": "ok"}:
        raise AssertionError(f"got {bid!r}")
    ep.send("A", "sold", {"price": 110})
    ep.send("B", "sold", {"price": 110})


def buyer(ep: Endpoint) -> None:
    quote = ep.recv("S").payload
    if quote != QUOTE:
        raise AssertionError(f"got {quote!r}")
    ep.send("S", "bid", {"note": "ok", "price": 110})  # any order of keys
    if ep.recv("S") != ("sold", {"price": 110}):
        raise AssertionError("not sold")


def watcher(ep: Endpoint) -> None:
    if ep.recv("S").payload != QUOTE:
        raise AssertionError("another quote")
    ep.recv("S")


# ---- the sender's monitor refuses -------------------------------------------------------------
def wrong_field_seller(ep: Endpoint) -> None:
    ep.send("A", "quote", {**QUOTE, "price": "120"})


def missing_field_seller(ep: Endpoint) -> None:
    ep.send("A", "quote", {"price": 120, "by": "Sam"})


def wrong_nested_field_seller(ep: Endpoint) -> None:
    ep.send("A", "quote", {**QUOTE, "where": Point("1", 2.5)})  # type: ignore[arg-type]


# ---- the receiver's monitor refuses: the sender bypasses its own ------------------------------
def smuggling_seller(ep: Endpoint) -> None:
    channel, _ = ep._out["A"]
    channel.put(("quote", {**QUOTE, "extra": 1}))
