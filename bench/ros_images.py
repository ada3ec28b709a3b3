#!/usr/bin/env python3
"""Images per second of 640x480 rgb8 ``sensor_msgs/msg/Image`` on the ROS 2 topic ``/camera/color/image_raw``.

Each image is a rosbags ``sensor_msgs__msg__Image`` (Jazzy), encoding "rgb8", step 1920, its data a
1-D uint8 array of 921,600 bytes. With ``transport=Dds(...)`` the channel is a real ROS 2 topic: DDS topic
``rt/camera/color/image_raw``, type ``sensor_msgs::msg::dds_::Image_``, plain CDR. The ways, interleaved
in every repetition (so drift hits all):

  anodize -> anodize, ROS topic   two groups on this host, ``anodize.System(..., transport=Dds(...),
                   ros=RosBridge(topics={"C->V:color": "/camera/color/image_raw"}))`` on the ROS domain (a fresh run
                   id per run). Protocol ``mu t. C -> V : {more. C -> V : color(Image). t, stop}``: the
                   images go on the ROS topic, the tiny ``more`` before each (and ``stop``) on anodize's
                   own topic of the channel. The viewer checks every image's number and layout.
  anodize -> Fast DDS             the same image stream into an external role V (protocol
                   ``mu t. C -> V : color(Image). t``, ``RosBridge(external={"V"}, topics={"C->V": ...})``)
                   played by ``ros_peer listen-image`` (``tests/anodize/ros_peer/main.cpp``), an
                   independent ROS 2 node on eProsima Fast DDS 2.x with ROS 2's default QoS (reliable,
                   volatile, keep-last 10). Twice: with a 4 MiB UDP receive buffer (``--rcvbuf 4194304``)
                   and with the OS's default (``net.core.rmem_default``), since Fast DDS with a buffer
                   smaller than one image's burst of fragments loses fragments and waits for their repair.
                   The peer is started first (into an external role, anodize's start barrier waits until
                   some ROS node subscribes); the producer sends N images and then sleeps until the run's
                   timeout stops it ("stopped" is the expected end: the protocol never ends). The peer
                   prints each image's size and byte sum: every image must arrive, whole, in order (the
                   sums are checked against the images sent).
  anodize process                 the first way's system with ``transport=Processes()`` (no ROS topics;
                   large arrays go through shared memory), for reference.

Time: images per second from the first image's receipt to the last's, ``(N - 1) / seconds``: the Fast
DDS program measures only this (C++ steady_clock). For the anodize receivers also from the producer's
clock just before its first send to the last receipt, ``N / seconds``, as ``bench/dds.py`` does
(CLOCK_MONOTONIC, one clock for the machine). Target: at least 30 images/s (a camera's rate) in every
way and figure. The producers cycle through a pool of 8 images made before the clock starts, each
numbered in ``header.stamp.sec`` and its first 8 data bytes.

Process start-up and discovery are never timed: roles start after anodize's start barrier. Every wait
is bounded; a way that fails or times out shows as "failed" in the table and its error is kept in the
JSON; without g++ or Fast DDS the Fast DDS rows show "skipped: <reason>". Medians over --repeat
repetitions. ``ROS_DOMAIN_ID`` is set to 1 + pid % 200 (never 0, everyone's default domain).

Usage:
  .venv/bin/python bench/ros_images.py [--images 300] [--repeat 3] [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import datetime
import functools
import importlib.metadata
import itertools
import json
import os
import platform
import statistics
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parent
for _path in (str(REPO), str(BENCH)):  # bench/ too: group processes import ros_images_roles
    if _path not in sys.path:
        sys.path.insert(0, _path)
sys.path.append(str(REPO / "tests" / "anodize"))  # last: ros_peer, the Fast DDS program's builder
os.environ["PYTHONPATH"] = os.pathsep.join(
    p for p in (str(BENCH), str(REPO), os.environ.get("PYTHONPATH", "")) if p)
DOMAIN = 1 + os.getpid() % 200  # the ROS domain of this benchmark; 0 is everyone's default
os.environ["ROS_DOMAIN_ID"] = str(DOMAIN)  # before anodize reads it: the ROS side lives on this domain

import numpy as np  # noqa: E402
import pytest  # noqa: E402  # ros_peer reports a missing compiler or Fast DDS as a pytest skip
import ros_images_roles as roles  # noqa: E402
from ros_peer import finish_peer, ros_peer_binary, start_peer  # noqa: E402
from runs import LoadWatch, bench_env, print_table, write_results  # noqa: E402

import sessiontypes  # noqa: E402
from anodize import Dds, Inproc, Processes, RosBridge, System  # noqa: E402
from anodize._supervision.report import RoleStatus  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "ros_images.json"
DDS_BENCH_JSON = BENCH / "results" / "dds.json"
ROS_TOPIC = "/camera/color/image_raw"
DDS_TOPIC = "rt" + ROS_TOPIC
BIG_RCVBUF = 4 << 20  # 4 MiB: within Linux's usual net.core.rmem_max
WAYS = ("dds", "fastdds_4mib", "fastdds_default", "process")
LABELS = {
    "dds": "anodize -> anodize, ROS topic (dds)",
    "fastdds_4mib": "anodize -> Fast DDS ros_peer, rcvbuf 4 MiB",
    "fastdds_default": "anodize -> Fast DDS ros_peer, OS default rcvbuf",
    "process": "anodize -> anodize, process transport (shm)",
}
RCVBUF = {"fastdds_4mib": BIG_RCVBUF, "fastdds_default": 0}  # 0: the OS default (the peer sets nothing)
FIGURES = ("per_second", "per_second_from_start")  # first -> last receipt; producer start -> last receipt
MIN_RATE = 30.0
WAIT = 20.0  # seconds anodize's start barrier waits for the peers (a group, or a ROS node subscribing)
EXTERNAL_RATE = 20.0  # into the Fast DDS program the run lasts 10 s + N images at this rate (see below)
GLOBALS = {
    "internal": sessiontypes.loads(roles.CAMERA, "ros_images.proto").globals["Camera"],
    "external": sessiontypes.loads(roles.CAMERA_EXTERNAL, "ros_images_external.proto").globals["Camera"],
}
_runs = itertools.count()


class SkippedError(Exception):
    """A way that cannot run on this machine (shown as "skipped: <reason>", not "failed")."""


# ---- running one measurement ----------------------------------------------------------------
def anodize_to_anodize(transport: str, n: int, timeout: float) -> dict[str, Any]:
    """Ways 1 and 3: two groups; the viewer's first and last receipt, and the producer's start."""
    with bench_env(roles.ENV, images=n) as (_, found):
        if transport == "dds":
            system = System(GLOBALS["internal"], transport=Dds(run_id=f"rosimg{os.getpid()}_{next(_runs)}", wait=WAIT),
                            ros=RosBridge(topics=roles.CAMERA_TOPICS))
        else:
            system = System(GLOBALS["internal"], transport=Processes() if transport == "process" else Inproc())
        system.group("camera").role("C", roles.camera)
        system.group("viewer").role("V", roles.viewer)
        report = system.run(timeout=timeout)
        if not report.ok:
            raise RuntimeError(f"anodize ({transport}) run failed:\n{report.summary()}")
        start, end = found("start")["start"], found("end")
        if end["count"] != n or end["bad"]:
            raise RuntimeError(f"{end['count']} of {n} images arrived, {end['bad']} wrong or out of order")
        seconds = end["last"] - end["first"]
        return {"count": n, "seconds": seconds, "per_second": (n - 1) / seconds,
                "seconds_from_start": end["last"] - start, "per_second_from_start": n / (end["last"] - start)}


@functools.cache
def peer_binary() -> str:
    """The built Fast DDS program (built once per machine and source version by ``tests/anodize/ros_peer.py``).

    Raises:
        SkippedError: no g++ or no Fast DDS 2.x development packages here.
        RuntimeError: the build failed (a bug in the peer).
    """
    try:
        return str(ros_peer_binary())
    except pytest.skip.Exception as skip:
        raise SkippedError(str(skip.msg)) from None
    except pytest.fail.Exception as fail:
        raise RuntimeError(str(fail.msg)) from None


@functools.cache
def expected_sums(n: int) -> tuple[int, ...]:
    """The byte sum of each image sent, as ``listen-image`` prints it (uint32; no wrap at 921,600 bytes)."""
    rest = [int(image.data[8:].sum(dtype=np.uint64)) for image in roles.image_pool()]
    return tuple(rest[i % roles.POOL] + sum(i.to_bytes(8, "little")) for i in range(n))


def external_timeout(n: int) -> float:
    """Seconds the run into the Fast DDS program lasts (it ends by this timeout: the protocol never ends)."""
    return 10.0 + n / EXTERNAL_RATE


def anodize_to_fastdds(n: int, rcvbuf: int) -> dict[str, Any]:
    """Way 2: the producer into the external role V, played by ``ros_peer listen-image``."""
    peer_binary()  # skipped (or failed) before anything starts
    run_timeout = external_timeout(n)
    peer_timeout = int(WAIT + run_timeout + 10)  # from the peer's own start: it outlives the run
    with bench_env(roles.ENV, images=n) as (_, found):
        peer = start_peer("listen-image", topic=DDS_TOPIC, domain=DOMAIN, count=n, timeout=peer_timeout,
                          rcvbuf=rcvbuf)
        try:
            system = System(GLOBALS["external"], transport=Dds(run_id=f"rosimg{os.getpid()}_{next(_runs)}", wait=WAIT),
                            ros=RosBridge(topics=roles.CAMERA_EXTERNAL_TOPICS, external=frozenset({"V"})))
            system.group("camera").role("C", roles.camera_to_ros)
            report = system.run(timeout=run_timeout)
        finally:
            code, out, err = finish_peer(peer, peer_timeout + 10)  # bounded: killed if it outlives that
        lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
        summary = lines[-1] if lines and "images" in lines[-1] else None
        role = report.roles["C"]
        if role.status not in (RoleStatus.DONE, RoleStatus.STOPPED) or role.error is not None:
            raise RuntimeError(f"anodize run failed:\n{report.summary()}")
        if summary is None:
            raise RuntimeError(f"ros_peer printed no summary (exit {code}):\n{out[-2000:]}{err[-2000:]}")
        images = lines[:-1]
        if code != 0 or summary["images"] != n:
            raise RuntimeError(f"{summary['images']} of {n} images reached Fast DDS before the run's timeout "
                               f"({run_timeout:g} s; {summary['per_second']:.1f} images/s over those); "
                               f"ros_peer exit {code}: {err[-500:]}")
        layout = {"width": roles.WIDTH, "height": roles.HEIGHT, "encoding": "rgb8", "bytes": roles.SIZE}
        bad = sum(1 for image, total in zip(images, expected_sums(n), strict=False)
                  if {k: image.get(k) for k in layout} != layout or image.get("sum") != total)
        if len(images) != n or bad:
            raise RuntimeError(f"{len(images)} of {n} images printed, {bad} wrong, cut or out of order")
        start, sent = found("start")["start"], found("sent")["sent"]
        return {"count": n, "seconds": summary["seconds"], "per_second": summary["per_second"],
                "send_seconds": sent - start, "send_per_second": n / (sent - start), "rcvbuf": rcvbuf,
                "run_timeout": run_timeout, "anodize_status": str(role.status)}


def run_way(way: str, n: int, timeout: float) -> dict[str, Any]:
    if way in RCVBUF:
        return anodize_to_fastdds(n, RCVBUF[way])
    return anodize_to_anodize(way, n, timeout)


def attempt(measure: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """One sample, or why there is none (printed in the table, kept in the JSON)."""
    load = os.getloadavg()[0]
    try:
        return {**measure(), "load_1min": load}
    except SkippedError as skip:
        print(f"  skipped: {skip}", file=sys.stderr)
        return {"skipped": str(skip), "load_1min": load}
    except Exception as error:  # a failed way must not end the benchmark
        print(f"  failed: {error}", file=sys.stderr)
        return {"error": f"{type(error).__name__}: {error}", "traceback": traceback.format_exc(), "load_1min": load}


def measure(repeat: int, n: int, timeout: float) -> dict[str, Any]:
    """``repeat`` interleaved samples of every way; the median of each figure over the good ones."""
    samples: dict[str, list[dict[str, Any]]] = {way: [] for way in WAYS}
    for r in range(repeat):
        for way in WAYS:
            print(f"images: {way}, repetition {r + 1}/{repeat}", file=sys.stderr, flush=True)
            samples[way].append(attempt(lambda way=way: run_way(way, n, timeout)))  # type: ignore[misc]
    median: dict[str, dict[str, float | None]] = {}
    for way, got in samples.items():
        good = [s for s in got if "error" not in s and "skipped" not in s]
        median[way] = {figure: (statistics.median(s[figure] for s in good) if good and figure in good[0] else None)
                       for figure in FIGURES}
    return {"samples": samples, "median": median}


# ---- output ---------------------------------------------------------------------------------
def _cell(way: str, found: dict[str, Any], figure: str) -> str:
    value = found["median"][way][figure]
    if value is not None:
        return f"{value:,.1f}"
    got = found["samples"][way]
    if got and all("skipped" in s for s in got):  # the reason once, in the first figure's column
        return f"skipped: {got[0]['skipped']}" if figure == FIGURES[0] else "skipped"
    if any("error" not in s and "skipped" not in s for s in got):
        return "n/a"  # the way ran, but has no such figure (the Fast DDS program times first -> last only)
    return "failed"


def table(found: dict[str, Any]) -> list[list[str]]:
    yes = {True: "yes", False: "NO", None: "n/a"}
    rows = [["way", "images/s, first -> last receipt", "images/s, producer start -> last receipt",
             "target", "met?"]]
    found["met"] = {}
    for way in WAYS:
        med = found["median"][way]
        shown = [med[f] for f in FIGURES if med[f] is not None]
        met = None if not shown else all(v >= MIN_RATE for v in shown)
        if med["per_second"] is None and any("error" in s for s in found["samples"][way]):
            met = False  # it failed: not met
        found["met"][way] = met
        rows.append([LABELS[way], *(_cell(way, found, f) for f in FIGURES), f">= {MIN_RATE:g} images/s", yes[met]])
    return rows


def rmem_default() -> int | None:
    try:
        return int(Path("/proc/sys/net/core/rmem_default").read_text())
    except (OSError, ValueError):
        return None


def dds_bench_frames() -> dict[str, Any] | None:
    """``bench/dds.py``'s last frames/s (raw numpy frames over anodize's own DDS topic), if it was run."""
    try:
        document = json.loads(DDS_BENCH_JSON.read_text(encoding="utf-8"))
        return {"date": document["date"], "frames": document["options"]["frames"],
                "repeat": document["options"]["repeat"], "median": document["frames"]["median"]}
    except (OSError, ValueError, KeyError):
        return None


def notes(found: dict[str, Any], n: int, rmem: int | None) -> list[str]:
    rmem_text = f"{rmem:,} bytes here" if rmem is not None else "unknown here"
    lines = [
        (f"- anodize -> anodize (dds and process): each image is preceded by a tiny `more` (the protocol's "
         f"choice to go on); with dds it goes on anodize's own DDS topic of the channel, the image on ROS topic "
         f"{ROS_TOPIC} (DDS {DDS_TOPIC}, sensor_msgs::msg::dds_::Image_). So every image costs two messages."),
        ("- anodize -> Fast DDS: images only, every one on the ROS topic (the external role V is `ros_peer "
         "listen-image`, ROS 2 default QoS: reliable, volatile, keep-last 10). Its figure is the program's own "
         "(first to last receipt, C++ steady_clock); it does not know the producer's start, hence n/a."),
        (f"- Two Fast DDS rows: an image (~922 KB of CDR) leaves Cyclone as ~690 DDS fragments in one burst; "
         f"Fast DDS's socket keeps the OS default UDP receive buffer (net.core.rmem_default, {rmem_text}) "
         f"unless told otherwise, smaller than one image, so datagrams can be dropped and then wait for the "
         f"reliable writer's repair; `--rcvbuf 4194304` (4 MiB) holds a few images. "
         f"tests/anodize/test_ros_peer.py saw 2-3 images/s with the default buffer (20 images from a plain "
         f"Cyclone writer); the default-buffer row measures it with anodize's writer."),
        (f"- Into Fast DDS the run ends by its timeout ({external_timeout(n):g} s = 10 s + N/{EXTERNAL_RATE:g}); "
         f"its producer is then `stopped` (the protocol never ends), which is the expected end. The peer's "
         f"byte sums of all N images are checked against what was sent (order and integrity)."),
    ]
    sends = {way: [s["send_per_second"] for s in found["samples"][way] if "send_per_second" in s] for way in RCVBUF}
    if any(sends.values()):
        lines.append("- The producer's own rate into Fast DDS (its start to its last send returning; the reliable "
                     "writer holds it back while the reader lags), median: " + ", ".join(
                         f"{LABELS[way].split(', ')[1]} {statistics.median(got):,.1f} images/s"
                         for way, got in sends.items() if got) + ".")
    other = found.get("dds_bench_frames")
    if other is not None:
        lines.append(f"- For comparison, bench/dds.py ({other['date']}, {other['frames']} frames, median of "
                     f"{other['repeat']}; not re-measured here): 640x480x3 uint8 numpy frames over anodize's own "
                     f"DDS topic (codec frames, not ROS CDR) {other['median'].get('dds') or 0:,.1f} frames/s, "
                     f"raw Cyclone {other['median'].get('raw') or 0:,.1f}, process "
                     f"{other['median'].get('process') or 0:,.1f}.")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--images", type=int, default=300, help="images per run")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions of every way")
    parser.add_argument("--timeout", type=float, default=120.0,
                        help="seconds an anodize -> anodize run may take (into Fast DDS: 10 s + images/20)")
    parser.add_argument("--quick", action="store_true", help="smoke test: 50 images, 1 repetition")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"default {DEFAULT_JSON}")
    args = parser.parse_args(argv)
    if args.quick:
        args.images, args.repeat = min(args.images, 50), 1
    if args.images < 2:
        parser.error("--images: at least 2 (rates are taken from the first to the last receipt)")

    started = time.monotonic()
    watch = LoadWatch()
    load_start = os.getloadavg()
    found = measure(args.repeat, args.images, args.timeout)
    load_end = os.getloadavg()
    found["dds_bench_frames"] = dds_bench_frames()
    rows = table(found)
    rmem = rmem_default()
    cyclone = importlib.metadata.version("cyclonedds")
    try:
        peer = peer_binary()
    except (SkippedError, RuntimeError) as why:
        peer = f"none ({why})"
    how = (f"640x480 rgb8 sensor_msgs/msg/Image on ROS topic {ROS_TOPIC}, {args.images:,} images per run, "
          f"median of {args.repeat}; {os.cpu_count()} CPUs, Python {platform.python_version()}, Cyclone DDS "
          f"{cyclone}, ROS_DOMAIN_ID {DOMAIN}; load average {load_start[0]:.2f} at the start, "
          f"{load_end[0]:.2f} at the end")
    print(how)
    print()
    print_table(rows, (0, 3, 4))
    print()
    for line in notes(found, args.images, rmem):
        print(line)

    document = {
        "benchmark": "ros_images",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                    "machine": platform.machine(), "python": platform.python_version(),
                    "numpy": np.__version__, "cyclonedds": cyclone, "rosbags": importlib.metadata.version("rosbags"),
                    "net_core_rmem_default": rmem, "ros_peer": peer},
        "load_average": {"start": list(load_start), "end": list(load_end)},
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "ros_domain_id": DOMAIN,
        "topic": {"ros": ROS_TOPIC, "dds": DDS_TOPIC, "type": "sensor_msgs::msg::dds_::Image_"},
        "external_run_timeout": external_timeout(args.images),
        "min_rate": MIN_RATE,
        "wall_seconds": time.monotonic() - started,
        "table": rows,
        "notes": notes(found, args.images, rmem),
        "images": found,
    }
    write_results(args.json, document, started, title="ROS 2 images per second", how=how, watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
