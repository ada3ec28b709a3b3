"""Dataclass payloads and role functions for the field-check tests (module level: group processes
import them, and protocols name the classes as ``"payload_roles:Point"``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from anodize import Endpoint


@dataclass(frozen=True)
class Point:
    x: int
    y: float


@dataclass(frozen=True)
class Track:
    """Points, an optional name and a greyscale image: nested dataclasses, a union, an array."""

    points: list[Point]
    name: str | None
    image: npt.NDArray[np.uint8]


def good_track() -> Track:
    return Track([Point(1, 2.5), Point(2, 3)], None, np.zeros((2, 2), np.uint8))  # y=3: an int fits float


def bad_track() -> Track:
    return Track([Point(1, 2.5), Point("b", 3.0)], "t", np.zeros((2, 2), np.uint8))  # type: ignore[arg-type]


# ---- the sender's monitor refuses: nothing is sent -------------------------------------------
def bad_point_sender(ep: Endpoint) -> None:
    ep.send("B", "point", Point("a", 1.0))  # type: ignore[arg-type]


def bad_track_sender(ep: Endpoint) -> None:
    ep.send("B", "point", Point(1, 1.0))
    ep.send("B", "track", bad_track())


# ---- the receiver's monitor refuses: the sender bypasses its own ------------------------------
def smuggling_point_sender(ep: Endpoint) -> None:
    channel, _ = ep._out["B"]
    channel.put(("point", Point("a", 1.0)))  # type: ignore[arg-type]


def smuggling_track_sender(ep: Endpoint) -> None:
    ep.send("B", "point", Point(1, 1.0))
    channel, _ = ep._out["B"]
    channel.put(("track", bad_track()))


# ---- conforming ------------------------------------------------------------------------------
def good_sender(ep: Endpoint) -> None:
    ep.send("B", "point", Point(1, 1.0))
    ep.send("B", "track", good_track())


def receiver(ep: Endpoint) -> None:
    point = ep.recv("A").payload
    if point != Point(1, 1.0):
        raise AssertionError(f"got {point!r}")
    track = ep.recv("A").payload
    if track.points != good_track().points or track.image.dtype != np.uint8:
        raise AssertionError(f"got {track!r}")
