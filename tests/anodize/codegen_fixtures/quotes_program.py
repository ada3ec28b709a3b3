"""The Quotes protocol (named payloads, multicasts) written against its generated typed states.

mypy --strict accepts this program; the tests also run it on anodize's runtime.
"""

from __future__ import annotations

from typing import assert_never

import quotes_a
import quotes_b
import quotes_s
from payloads import Point


def seller(start: quotes_s.Initial) -> quotes_s.End:
    where = Point(1.0, 2.5)
    told = start.send_quote(120, where, "Sam").send_quote(price=120, where=where, from_prime="Sam")
    bid, deciding = told.recv_bid()
    if bid["price"] >= 100:
        return deciding.select_sold(bid["price"], "A").send_sold(price=bid["price"], buyer="A")
    return deciding.select_unsold().send_unsold()


def buyer(start: quotes_a.Initial) -> quotes_a.End:
    quote, bidding = start.recv_quote()
    assert quote == {"price": 120, "where": Point(1.0, 2.5), "from'": "Sam"}
    sender = quote["from'"]
    outcome = bidding.send_bid(quote["price"] - 10, note=f"to {sender}").offer()
    match outcome:
        case quotes_a.State2Sold(sold, end):
            assert sold == {"price": 110, "buyer": "A"}
            return end
        case quotes_a.State2Unsold(end):
            return end
        case _:
            assert_never(outcome)


def watcher(start: quotes_b.Initial) -> quotes_b.End:
    quote, waiting = start.recv_quote()
    price: int = quote["price"]
    outcome = waiting.offer()
    match outcome:
        case quotes_b.State1Sold(sold, end):
            assert sold["price"] <= price
            return end
        case quotes_b.State1Unsold(end):
            return end
        case _:
            assert_never(outcome)
