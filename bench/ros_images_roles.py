"""Role functions for ``bench/ros_images.py``.

Module level on purpose: anodize's group processes import them by name. The roles take
their settings from the JSON in the environment variable ``ANODIZE_BENCH_ROS_IMAGES``
(set by the parent before a run; spawned interpreters inherit it); every measuring
function writes what it measured as JSON to ``<out>/<name>.json``, where the parent reads
it after the run.

Clocks: ``time.monotonic()`` is CLOCK_MONOTONIC on Linux, one clock for the whole
machine, so a start taken in the producer and an end taken in the consumer can be
subtracted.

The images are ``sensor_msgs/msg/Image`` messages (rosbags' Jazzy classes), 640x480
``rgb8``, step 1920, their data a 1-D uint8 array of 921,600 bytes. The producer cycles
through a pool of 8 made before its clock starts and numbers each image it sends, in
``header.stamp.sec`` and in the first 8 bytes of its data; the consumer checks both.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

from anodize import Endpoint

ENV = "ANODIZE_BENCH_ROS_IMAGES"
HEIGHT, WIDTH, CHANNELS = 480, 640, 3
STEP = WIDTH * CHANNELS
SIZE = HEIGHT * STEP  # 921,600 bytes
POOL = 8  # distinct images the sender cycles through (made before the clock starts)

# The protocols. Ways 1 and 3: a tiny "more" (on anodize's own topic) before every image.
# Way 2: images only, every message on the ROS topic, into the external role V (Fast DDS).
CAMERA = """
type Image = "ros:sensor_msgs/msg/Image"
global Camera(C, V) = mu t. C -> V : {more. C -> V : color(Image). t, stop}
"""
CAMERA_TOPICS = {"C->V:color": "/camera/color/image_raw"}
CAMERA_EXTERNAL = """
type Image = "ros:sensor_msgs/msg/Image"
global Camera(C, V) = mu t. C -> V : color(Image). t
"""
CAMERA_EXTERNAL_TOPICS = {"C->V": "/camera/color/image_raw"}


def config() -> dict[str, Any]:
    return json.loads(os.environ[ENV])  # type: ignore[no-any-return]


def report(name: str, data: dict[str, Any]) -> None:
    """Write ``data`` where the parent will look for it (atomically: write, then rename)."""
    folder = Path(config()["out"])
    tmp = folder / f".{name}.json"
    tmp.write_text(json.dumps(data), encoding="utf-8")
    tmp.rename(folder / f"{name}.json")


# ---- images ---------------------------------------------------------------------------------
def image_pool() -> list[Image]:
    """The same 8 images in every process (a fixed seed): ``bench/ros_images.py`` knows their byte sums."""
    rng = np.random.default_rng(2024)
    return [Image(header=Header(stamp=Time(sec=0, nanosec=0), frame_id="camera_color_optical_frame"),
                  height=HEIGHT, width=WIDTH, encoding="rgb8", is_bigendian=0, step=STEP,
                  data=rng.integers(0, 256, size=SIZE, dtype=np.uint8)) for _ in range(POOL)]


def stamp(image: Image, index: int) -> Image:
    """Number the image in ``header.stamp.sec`` and in the first 8 bytes of its data."""
    image.header.stamp.sec = index
    image.data[:8] = np.frombuffer(index.to_bytes(8, "little"), np.uint8)
    return image


class ImageSink:
    """What the anodize receiver does with an image: check its number, shape and encoding, count."""

    def __init__(self) -> None:
        self.count = 0
        self.bad = 0
        self.touched = 0
        self.first: float | None = None  # time.monotonic() at the first and the last image's receipt
        self.last: float | None = None

    def take(self, image: Image) -> None:
        self.last = time.monotonic()
        if self.first is None:
            self.first = self.last
        data = image.data
        if (image.header.stamp.sec != self.count or image.encoding != "rgb8" or image.step != STEP
                or image.height != HEIGHT or image.width != WIDTH or len(data) != SIZE
                or int.from_bytes(np.asarray(data[:8], np.uint8).tobytes(), "little") != self.count):
            self.bad += 1
        self.touched += int(np.asarray(data[::STEP * 96], np.uint8).sum(dtype=np.uint64))  # a byte of every 96th row
        self.count += 1


# ---- anodize roles --------------------------------------------------------------------------
def camera(ep: Endpoint) -> None:
    """Ways 1 and 3: ``more`` then an image, N times, then ``stop``."""
    n = config()["images"]
    pool = image_pool()
    report("start", {"start": time.monotonic()})
    for i in range(n):
        ep.send("V", "more")
        ep.send("V", "color", stamp(pool[i % POOL], i))
    ep.send("V", "stop")
    report("sent", {"sent": time.monotonic()})


def viewer(ep: Endpoint) -> None:
    sink = ImageSink()
    while ep.recv("C").label == "more":
        sink.take(ep.recv("C").payload)
    report("end", {"first": sink.first, "last": sink.last, "count": sink.count, "bad": sink.bad})


def camera_to_ros(ep: Endpoint) -> None:
    """Way 2: N images to the external role (a Fast DDS node), then wait until the run stops
    (the protocol never ends: the run ends by its timeout, and this role is "stopped")."""
    n = config()["images"]
    pool = image_pool()
    report("start", {"start": time.monotonic()})
    for i in range(n):
        ep.send("V", "color", stamp(pool[i % POOL], i))
    report("sent", {"sent": time.monotonic()})
    ep.sleep(float("inf"))
