"""The roles of examples/two_hosts: a camera and wheels on the robot, a driver on the base station."""

from __future__ import annotations

import zlib

import numpy as np

from anodize import Endpoint

FRAMES = 100
SHAPE = (480, 640, 3)


def camera(ep: Endpoint) -> None:
    """Send FRAMES frames, each after the wheels have moved; then say done."""
    rng = np.random.default_rng(7)
    for _ in range(FRAMES):
        frame = rng.integers(0, 256, SHAPE, dtype=np.uint8)
        ep.send("Driver", "frame", frame)
        ep.recv("Wheels")
    ep.send("Driver", "done")


def driver(ep: Endpoint) -> None:
    """Steer by the frame's brightness; the checksum shows the frame arrived whole."""
    while True:
        label, frame = ep.recv("Camera")
        if label == "done":
            ep.send("Wheels", "stop")
            return
        steer = float(frame.mean() / 255.0 - 0.5) + (zlib.crc32(frame.tobytes()) % 1000) * 1e-9
        ep.send("Wheels", "steer", steer)


def wheels(ep: Endpoint) -> None:
    while True:
        label, _ = ep.recv("Driver")
        if label == "stop":
            return
        ep.send("Camera", "moved")
