"""Role functions for the evidence tests: a buyer and a seller whose every payload differs."""

from __future__ import annotations

from anodize import Endpoint

TITLES = 12


def buyer(ep: Endpoint) -> None:
    for number in range(TITLES):
        ep.send("S", "title", f"title {number}")
        ep.recv("S")
    ep.send("S", "done")


def seller(ep: Endpoint) -> None:
    quoted = 0
    while True:
        label, _ = ep.recv("B")
        if label == "done":
            return
        quoted += 1
        ep.send("B", "quote", 100 + quoted)
