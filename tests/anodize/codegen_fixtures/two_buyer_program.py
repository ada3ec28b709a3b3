"""The two-buyer protocol written against its generated typed states.

mypy --strict accepts this program; the tests also run it on anodize's runtime.
Each function returns the role's ``End`` state, so a function that stops early
does not type-check either.
"""

from __future__ import annotations

from typing import assert_never

import twobuyer_b1
import twobuyer_b2
import twobuyer_s

PRICE = 60


def buyer1(start: twobuyer_b1.Initial) -> twobuyer_b1.End:
    quote, sharing = start.send_title("War and Peace").recv_quote()
    return sharing.send_share(quote // 2)


def buyer2(start: twobuyer_b2.Initial) -> twobuyer_b2.End:
    quote, waiting = start.recv_quote()
    share, deciding = waiting.recv_share()
    if quote - share > 50:
        return deciding.select_quit()
    date, end = deciding.select_ok("1 Wonderland Road").recv_date()
    assert date == "tomorrow"
    return end


def seller(start: twobuyer_s.Initial) -> twobuyer_s.End:
    title, quoting = start.recv_title()
    assert title == "War and Peace"
    outcome = quoting.send_quote(PRICE).send_quote(PRICE).offer()
    match outcome:
        case twobuyer_s.State3Ok(address, dating):
            assert address == "1 Wonderland Road"
            return dating.send_date("tomorrow")
        case twobuyer_s.State3Quit(end):
            return end
        case _:
            assert_never(outcome)
