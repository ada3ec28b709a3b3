"""Role functions for the send_many tests (module level, so group processes import them)."""

from __future__ import annotations

import json
import os

from anodize import Endpoint

COUNT = 5000


def batch_sender(ep: Endpoint) -> None:
    sent = ep.send_many("B", "num", range(COUNT))
    assert sent == COUNT
    ep.send("B", "fin")


def counting_receiver(ep: Endpoint) -> None:
    got = []
    while (message := ep.recv("A")).label == "num":
        got.append(message.payload)
    with open(os.environ["SEND_MANY_OUT"], "w", encoding="utf-8") as out:
        json.dump(got, out)
