"""The live view: ``anodize run --foxglove`` seen by a client speaking Foxglove's WebSocket protocol.

The client (``websockets``) sees every label of every channel advertised with its ROS 2
schema, and the status channel; it subscribes and receives messages as CDR; it
publishes Joys on ``/joy``, which reach the role that sends ``/joy`` (through its
monitor: ``R`` writes down what it received), while a malformed one is rejected and
named in the report, and the run goes on.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import struct
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1]))

import live_roles

from anodize._live import STATUS_TOPIC, open_live_view
from anodize._ros import ros_type
from anodize._tools.cli import main
from anodize.errors import AnodizeError

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")

JOY = ros_type("sensor_msgs/msg/Joy")
CLIENT_AXES = [0.25, -0.5]
TOPICS = {"/joy": "sensor_msgs/msg/Joy", "/camera/image": "sensor_msgs/msg/Image",
          "/anodize/R/L/seen": "std_msgs/msg/String", "/anodize/P/L/go": "std_msgs/msg/String",
          "/anodize/L/R/stop": "std_msgs/msg/String"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _client_joy() -> bytes:
    from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
    from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

    return JOY.serialize(JOY.cls(header=Header(stamp=Time(sec=1, nanosec=0), frame_id="foxglove"),
                                 axes=np.array(CLIENT_AXES, np.float32), buttons=np.array([1], np.int32)))


class Client:
    """A Foxglove WebSocket client in a thread of its own: what it saw, for the test to check."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.advertised: dict[str, dict[str, Any]] = {}
        self.joys: list[Any] = []
        self.statuses: list[dict[str, Any]] = []
        self.published = 0
        self.done = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            asyncio.run(asyncio.wait_for(self._session(), timeout=40.0))
        except BaseException as error:
            self.error = error

    async def _connect(self) -> Any:
        for _ in range(200):
            try:
                return await asyncio.wait_for(websockets.connect(
                    f"ws://127.0.0.1:{self.port}", subprotocols=["foxglove.sdk.v1"]), timeout=2.0)
            except OSError:
                await asyncio.sleep(0.05)
        raise TimeoutError("the live view never listened")

    async def _session(self) -> None:
        ws = await self._connect()
        async with ws:
            assert ws.subprotocol == "foxglove.sdk.v1"
            while not set(TOPICS) | {STATUS_TOPIC} <= set(self.advertised):
                self._take(await asyncio.wait_for(ws.recv(), timeout=15.0))
            subscriptions = dict(enumerate(["/joy", STATUS_TOPIC], start=1))
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": n, "channelId": self.advertised[topic]["id"]} for n, topic in subscriptions.items()]}))
            await ws.send(json.dumps({"op": "advertise", "channels": [
                {"id": 7, "topic": "/joy", "encoding": "cdr", "schemaName": "sensor_msgs/msg/Joy"}]}))
            await ws.send(b"\x01" + struct.pack("<I", 7) + b"\x00\x01\x00\x00not a joy")  # rejected
            joy = b"\x01" + struct.pack("<I", 7) + _client_joy()
            with contextlib.suppress(websockets.ConnectionClosed):  # the run ended: the server closes
                while not self.done.is_set():
                    if self.statuses:  # the run's first status came: then the Joys that end it
                        await ws.send(joy)
                        self.published += 1
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout(0.05):  # take what comes for a while, then publish again
                            while True:
                                self._take(await ws.recv(), subscriptions)

    def _take(self, message: Any, subscriptions: dict[int, str] | None = None) -> None:
        if isinstance(message, (str, dict)):  # a JSON op
            op = json.loads(message) if isinstance(message, str) else message
            if op.get("op") == "advertise":
                for channel in op["channels"]:
                    self.advertised[channel["topic"]] = channel
            return
        assert message[0] == 1 and subscriptions is not None  # binary: message data
        subscription, _ = struct.unpack_from("<IQ", message, 1)
        payload = message[13:]
        if subscriptions[subscription] == "/joy":
            self.joys.append(JOY.deserialize(payload))
        else:
            self.statuses.append(json.loads(payload))


def test_a_foxglove_client_sees_every_channel_and_drives_the_joy_role(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        run_waits_for_client: Any) -> None:  # a HeldRun (conftest.py): the groups start once it subscribed
    (tmp_path / "pad.proto").write_text(live_roles.PROTOCOL, encoding="utf-8")
    system = tmp_path / "pad.toml"
    system.write_text(live_roles.SYSTEM, encoding="utf-8")
    monkeypatch.setenv("LIVE_TEST_OUT", str(tmp_path))
    monkeypatch.syspath_prepend(str(Path(__file__).parents[1]))
    port = _free_port()
    client = Client(port)
    try:
        code = main(["run", str(system), "--foxglove", str(port), "--quiet", "--timeout", "30"])
    finally:
        client.done.set()
        client.thread.join(timeout=10.0)
    out = capsys.readouterr().out
    assert run_waits_for_client.subscribed == [True], "the client never subscribed to the status topic"
    assert not client.thread.is_alive(), "the client did not close"
    assert client.error is None, repr(client.error)
    assert code == 0, out
    assert f"foxglove: serving the run live at ws://127.0.0.1:{port}" in out

    for topic, schema_name in TOPICS.items():  # ROS 2 schemas, CDR
        channel = client.advertised[topic]
        assert (channel["encoding"], channel["schemaName"], channel["schemaEncoding"]) == \
            ("cdr", schema_name, "ros2msg"), channel
    assert "float32[] axes" in client.advertised["/joy"]["schema"]
    assert client.advertised[STATUS_TOPIC]["encoding"] == "json"

    assert client.joys and all(isinstance(j, JOY.cls) for j in client.joys)  # subscribed: CDR that decodes
    assert client.statuses and {"pad", "robot"} <= set(client.statuses[-1]["groups"])
    assert {"state", "rate_hz", "memory_mib"} <= set(client.statuses[-1]["groups"]["pad"])

    seen = json.loads((tmp_path / "robot.json").read_text(encoding="utf-8"))
    assert seen.count(CLIENT_AXES) == live_roles.CLIENT_TAKES  # the client's Joys reached R, through P
    assert "client messages on /joy handed to their role" in out
    assert "foxglove: 1 client messages on /joy rejected; the first: " in out


def test_a_taken_port_is_an_error_naming_it() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(AnodizeError, match=rf"^the live view cannot serve on 127\.0\.0\.1:{port}: "):
            open_live_view(port)
