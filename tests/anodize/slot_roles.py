"""Role functions for the buffer hand-over tests (module level: group processes import them)."""

from __future__ import annotations

import gc
from dataclasses import dataclass

import numpy as np

from anodize import Endpoint, PeerFailedError

SHAPE = (240, 320, 3)  # 225 KiB: over the inline limit


@dataclass(frozen=True)
class Frame:
    """A numbered image."""

    index: int
    pixels: np.ndarray


def stale_source(ep: Endpoint) -> None:
    """Sends a buffer, lets its slot come back and be filled again, then sends the old one."""
    old = ep.buffer("B", SHAPE, np.uint8)
    old[:] = 1
    ep.send("B", "frame", Frame(1, old))
    ep.recv("B")  # dropped: the slot is free again
    new = ep.buffer("B", SHAPE, np.uint8, strict=True)  # the same slot, filled again
    new[:] = 2
    ep.send("B", "again", Frame(2, old))  # raises StaleBufferError: nothing is sent


def stale_sink(ep: Endpoint) -> None:
    first = ep.recv("A").payload
    if int(first.pixels.max()) != 1:
        raise AssertionError("the first frame arrived changed")
    del first
    gc.collect()
    ep.send("A", "dropped")
    try:
        message = ep.recv("A")
    except PeerFailedError:
        return
    raise AssertionError(f"frame {message.payload.index} arrived: {message.payload.pixels.max()}")
