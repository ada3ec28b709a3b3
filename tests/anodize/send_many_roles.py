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


def mixed_sender(ep: Endpoint) -> None:
    """Floats and ints to a float label: an int needs the full check at the receiver."""
    ep.send_many("B", "num", [float(i) if i % 3 else i for i in range(COUNT)])
    ep.send("B", "fin")


def batch_receiver(ep: Endpoint) -> None:
    got: list[object] = []
    batches = 0
    while True:
        messages = ep.recv_many("A", limit=256)
        batches += 1
        for message in messages:
            if message.label == "fin":
                with open(os.environ["SEND_MANY_OUT"], "w", encoding="utf-8") as out:
                    json.dump({"got": got, "batches": batches}, out)
                return
            got.append(message.payload)


ARRAYS = 12  # more than a ring's 8 slots


def array_batch_sender(ep: Endpoint) -> None:
    import numpy as np

    ep.send_many("B", "frame", [np.full((300, 300), i, dtype=np.float64) for i in range(ARRAYS)])
    ep.send("B", "fin")


def array_receiver(ep: Endpoint) -> None:
    firsts = []
    while (message := ep.recv("A")).label == "frame":
        firsts.append(float(message.payload[0, 0]))
    with open(os.environ["SEND_MANY_OUT"], "w", encoding="utf-8") as out:
        json.dump(firsts, out)


def too_big_in_the_middle(ep: Endpoint) -> None:
    ep.send_many("B", "s", ["a", "b", "x" * (65 * 2**20)])  # the third is over a frame's limit


def string_receiver(ep: Endpoint) -> None:
    while True:
        ep.recv("A")


def frames_receiver(ep: Endpoint) -> None:
    """As ``counting_receiver``, noting also which decoder this process uses (compiled or not)."""
    from anodize._transport import frames

    got = []
    while (message := ep.recv("A")).label == "num":
        got.append(message.payload)
    with open(os.environ["SEND_MANY_OUT"], "w", encoding="utf-8") as out:
        json.dump({"compiled": frames.COMPILED, "got": got}, out)
