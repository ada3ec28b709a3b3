"""The live view under a slow client: bounded, counted, and below every group.

A Foxglove client subscribes to every channel and then reads slowly (a viewer on a bad
network): the run's roles still finish, the server holds a bounded amount, what was not
shown is counted per topic on the status topic and in the report, and the view's
threads (the SDK's too) run at the lowest priority the OS has. Every wait is bounded;
nothing here asserts a duration.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import socket
import struct
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

import sessiontypes

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import live_roles
import test_foxglove

from anodize import _live as live
from anodize._isolation.sched import SIDE_WORK_BELOW
from anodize._live import STATUS_TOPIC
from anodize._live.outbox import OUTBOX_BYTES, Outbox
from anodize._tools.cli import main

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")


READ_EVERY = 0.2    # seconds between two messages the slow client reads
JOY_EVERY = 0.3     # seconds between its Joys, at most: the pad takes Joys younger than 0.5 s
CLOSE_WITHIN = 1.0  # seconds the client waits for the server's closing frame


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_the_outbox_is_bounded_drops_the_oldest_and_counts_per_label() -> None:
    box = Outbox(limit=1000, large=100)
    for n in range(50):
        box.put(1, n, b"s" * 50)  # small: one queue, the oldest go
    assert box.held <= 1000 and box.dropped[1] == 30
    box.put(2, 100, b"L" * 200)
    box.put(2, 101, b"L" * 201)  # large: one slot per label, the newer replaces it
    assert box.dropped[2] == 1 and box.held <= 1000
    taken = box.take(timeout=1.0)
    small = [stamp for index, stamp, _ in taken if index == 1]
    assert small == list(range(50 - len(small), 50))  # the newest, in order: the oldest went
    assert box.dropped[1] == 50 - len(small)
    assert [(stamp, len(data)) for index, stamp, data in taken if index == 2] == [(101, 201)]
    assert box.peak <= 1000 and box.held == 0
    box.close()
    assert box.take(timeout=1.0) == []


class SlowClient:
    """A Foxglove client that reads one message in a while, its own Joys still published on time.

    It subscribes to the status topic first and waits for a status (the run's groups start only
    once it has subscribed: ``run_waits_for_client``), then to every channel, and from then on
    publishes a Joy at least every :data:`JOY_EVERY` seconds (younger than the pad's
    ``max_age``) while it reads one message each :data:`READ_EVERY` seconds: a slow reader,
    not a slow writer. Everything else waits in the server's queues. When done it closes
    within :data:`CLOSE_WITHIN` seconds, whatever it left unread.
    """

    def __init__(self, port: int) -> None:
        self.port = port
        self.statuses: list[dict[str, Any]] = []
        self.received = 0
        self.published = 0
        self.done = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            asyncio.run(asyncio.wait_for(self._session(), timeout=60.0))
        except BaseException as error:
            self.error = error

    async def _session(self) -> None:
        ws = None
        for _ in range(200):
            with contextlib.suppress(OSError):
                # close_timeout: unread messages fill its queue, so it would not see the server's
                # closing frame and would wait websockets' default 10 s for it.
                ws = await asyncio.wait_for(websockets.connect(
                    f"ws://127.0.0.1:{self.port}", subprotocols=["foxglove.sdk.v1"], max_size=None,
                    close_timeout=CLOSE_WITHIN), timeout=2.0)
                break
            await asyncio.sleep(0.05)
        assert ws is not None, "the live view never listened"
        async with ws:
            advertised: dict[str, int] = {}
            while not {"/joy", "/camera/image", STATUS_TOPIC} <= set(advertised):
                op = json.loads(await asyncio.wait_for(ws.recv(), timeout=15.0))
                if op.get("op") == "advertise":
                    advertised.update({c["topic"]: c["id"] for c in op["channels"]})
            topics = dict(enumerate(sorted(advertised), start=1))
            first = {n: topic for n, topic in topics.items() if topic == STATUS_TOPIC}
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": n, "channelId": advertised[topic]} for n, topic in first.items()]}))
            while not self.statuses:  # the groups are starting; the supervisor says so twice a second
                self._take(await asyncio.wait_for(ws.recv(), timeout=15.0), topics)
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": n, "channelId": advertised[topic]} for n, topic in topics.items() if n not in first]}))
            await ws.send(json.dumps({"op": "advertise", "channels": [
                {"id": 7, "topic": "/joy", "encoding": "cdr", "schemaName": "sensor_msgs/msg/Joy"}]}))
            joy = b"\x01" + struct.pack("<I", 7) + _joy()
            with contextlib.suppress(websockets.ConnectionClosed):
                while not self.done.is_set():
                    await ws.send(joy)
                    self.published += 1
                    with contextlib.suppress(TimeoutError):
                        message = await asyncio.wait_for(ws.recv(), timeout=JOY_EVERY - READ_EVERY)
                        self._take(message, topics)
                    await asyncio.sleep(READ_EVERY)  # a slow reader: everything else waits in the server's queues

    def _take(self, message: Any, topics: dict[int, str]) -> None:
        if isinstance(message, str):
            return
        self.received += 1
        subscription, _ = struct.unpack_from("<IQ", message, 1)
        if topics.get(subscription) == STATUS_TOPIC:
            self.statuses.append(json.loads(message[13:]))


def _joy() -> bytes:
    return test_foxglove._client_joy()


def test_a_slow_client_subscribed_to_everything_is_bounded_counted_and_below_every_group(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        run_waits_for_client: Any) -> None:  # a HeldRun (conftest.py)
    (tmp_path / "pad.proto").write_text(live_roles.PROTOCOL, encoding="utf-8")
    system = tmp_path / "pad.toml"
    system.write_text(live_roles.SYSTEM, encoding="utf-8")
    monkeypatch.setenv("LIVE_TEST_OUT", str(tmp_path))
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1]))
    port = _free_port()
    client = SlowClient(port)
    try:
        code = main(["run", str(system), "--foxglove", str(port), "--timeout", "40"])
    finally:
        client.done.set()
        client.thread.join(timeout=10.0)
    out = capsys.readouterr().out
    assert run_waits_for_client.subscribed == [True], "the client never subscribed to the status topic"
    assert not client.thread.is_alive(), "the slow client did not close"
    assert client.error is None, repr(client.error)
    assert code == 0, out
    # A slow reader's own Joys still reach the pad: it took them (not its 15 s giving up) and stopped the run.
    seen = json.loads((tmp_path / "robot.json").read_text(encoding="utf-8"))
    assert seen.count(test_foxglove.CLIENT_AXES) == live_roles.CLIENT_TAKES, (client.published, out)
    assert "client messages on /joy handed to their role" in out
    view = run_waits_for_client.views[0]
    assert view.outbox.peak <= OUTBOX_BYTES  # bounded, whatever the client did

    # Not shown is counted, per topic: the pad sends images at 50 Hz, the view shows 10 a second.
    assert view.not_shown().get("/camera/image", 0) > 0
    assert "foxglove: not shown, per topic: " in out and "/camera/image " in out
    assert client.statuses, "the slow client got no status at all"
    assert {"clients", "shown", "not_shown"} <= set(client.statuses[-1]["live"])

    # Every thread of the view, the SDK's own included, below every group.
    assert {"anodize-live-publish", "anodize-live-accept"} <= set(view.priorities)
    assert any(not name.startswith("anodize-live") for name in view.priorities), view.priorities
    below = f"nice {min(19, os.getpriority(os.PRIO_PROCESS, 0) + SIDE_WORK_BELOW)}"  # the supervisor's, then 5 down
    assert set(view.priorities.values()) == {below}, view.priorities  # the supervisor is not real time
    assert f"threads ran at {below}, the groups' taps at SCHED_FIFO 1" in out or \
        f"threads ran at {below}, the groups' taps at {below}" in out  # SCHED_FIFO where it is permitted


class _StuckChannel:
    """A Foxglove channel whose clients take nothing: ``log`` waits until released."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.logged = 0

    def log(self, data: bytes, log_time: int | None = None) -> None:
        self.release.wait(30)
        self.logged += 1


def test_a_stuck_client_never_blocks_the_threads_that_read_the_groups() -> None:
    from anodize._live.wire import HELLO, MESSAGE, send_frame
    from anodize.taps import TapRun

    protocol = sessiontypes.loads("global G(A, B) = mu t. A -> B : {image(bytes). t, pose(bytes). t}").globals["G"]
    machines = {role: protocol.project(role).fsm() for role in protocol.roles}
    view = live.open_live_view(0)
    try:
        view.begin(TapRun(protocol, machines, {"A": "g", "B": "g"}, {}, "inproc", {}))
        assert view.plan is not None and [x.label for x in view.plan.labels] == ["image", "pose"]
        stuck = view._channels[0] = view._channels[1] = _StuckChannel()
        image, pose = b"i" * 2**20, b"p" * 1000
        sent = threading.Event()

        def group() -> None:  # a group's tap, sending far more than the outbox holds
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
                sock.connect(view.socket_path)
                send_frame(sock, HELLO, 0, 0, b"g")
                for n in range(200):
                    send_frame(sock, MESSAGE, 0, n + 1, image)
                    send_frame(sock, MESSAGE, 1, n + 1, pose)
                sent.set()

        threading.Thread(target=group, daemon=True).start()
        # 200 MiB through a socket whose reader would stop if it waited for the stuck client.
        assert sent.wait(60), "the server's reader waited for a client"
        assert view.outbox.peak <= OUTBOX_BYTES
        stuck.release.set()
        notes = view.end(wait=10)
        assert view.outbox.dropped.get(0, 0) > 0  # images replaced by newer ones: counted
        assert view.not_shown()["/anodize/A/B/image"] == view.outbox.dropped[0]
        assert stuck.logged + sum(view.outbox.dropped.values()) == 400  # every message shown or counted
        assert any(note.startswith("foxglove: not shown, per topic: /anodize/A/B/image ") for note in notes), notes
    finally:
        view.close()
