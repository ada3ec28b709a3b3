"""The roles' log records in the live view: a Foxglove client subscribed to ``/rosout`` gets ``foxglove.Log``."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import struct
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from anodize import _live as live
from anodize._tools.cli import main

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")

REPO = Path(__file__).resolve().parents[3]
SUBSCRIBE_WITHIN = 30.0  # seconds the run waits for the client to subscribe to /rosout


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class LogClient:
    """Subscribes to /rosout and keeps what arrives, in a thread of its own."""

    def __init__(self, port: int, seen: Path, role: str, count: int) -> None:
        self.port = port
        self.seen, self.role, self.count = seen, role, count  # seen is made once role's count records came
        self.advertised: dict[str, dict[str, Any]] = {}
        self.logs: list[dict[str, Any]] = []
        self.done = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=lambda: self._guard(), daemon=True)
        self.thread.start()

    def _guard(self) -> None:
        try:
            asyncio.run(asyncio.wait_for(self._session(), timeout=60.0))
        except BaseException as error:
            self.error = error

    async def _session(self) -> None:
        for _ in range(400):
            try:
                ws = await asyncio.wait_for(websockets.connect(
                    f"ws://127.0.0.1:{self.port}", subprotocols=["foxglove.sdk.v1"]), timeout=2.0)
                break
            except OSError:
                await asyncio.sleep(0.05)
        else:
            raise TimeoutError("the live view never listened")
        async with ws:
            while "/rosout" not in self.advertised:
                self._take(await asyncio.wait_for(ws.recv(), timeout=15.0))
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": 1, "channelId": self.advertised["/rosout"]["id"]}]}))
            with contextlib.suppress(websockets.ConnectionClosed):
                while not self.done.is_set():
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout(0.05):
                            self._take(await ws.recv())

    def _take(self, message: Any) -> None:
        if isinstance(message, str):
            op = json.loads(message)
            if op.get("op") == "advertise":
                for channel in op["channels"]:
                    self.advertised[channel["topic"]] = channel
            return
        assert message[0] == 1
        subscription, _ = struct.unpack_from("<IQ", message, 1)
        assert subscription == 1
        self.logs.append(json.loads(message[13:]))
        if sum(log["name"] == self.role for log in self.logs) >= self.count:
            self.seen.touch()


def test_a_foxglove_client_gets_the_roles_records_as_foxglove_log(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    opened = live.open_live_view
    subscribed: list[bool] = []

    def open_view(port: int = live.DEFAULT_PORT, host: str = "127.0.0.1") -> Any:
        view = opened(port, host)
        begin = view.begin

        def begin_when_subscribed(run: Any) -> Any:  # the roles log only once the client listens
            plan = begin(run)
            deadline = time.monotonic() + SUBSCRIBE_WITHIN
            while not any("/rosout" in t for t in list(view.clients.values())) and time.monotonic() < deadline:
                time.sleep(0.01)
            subscribed.append(any("/rosout" in t for t in list(view.clients.values())))
            return plan

        view.begin = begin_when_subscribed
        return view

    monkeypatch.setattr(live, "open_live_view", open_view)
    # P logs, then waits for the client to have its records (the run is live when they are sent);
    # C logs as the run ends.
    seen = tmp_path / "seen"
    monkeypatch.setenv("LOGGING_TEST_SEEN", str(seen))
    system = tmp_path / "system.toml"
    system.write_text(f'protocol = "{REPO / "protocols" / "stream.proto"}"\nglobal = "Stream"\n'
                      f'transport = "process"\npythonpath = ["{REPO / "tests" / "anodize"}"]\n'
                      '[groups.a]\nroles = { P = "logging_roles:held_producer" }\n'
                      '[groups.b]\nroles = { C = "logging_roles:consumer" }\n', encoding="utf-8")
    port = _free_port()
    client = LogClient(port, seen, "P", 5)
    try:
        code = main(["run", str(system), "--foxglove", str(port), "--quiet", "--timeout", "60"])
    finally:
        client.done.set()
        client.thread.join(timeout=10.0)
    out = capsys.readouterr().out
    assert subscribed == [True], "the client never subscribed to /rosout"
    assert client.error is None, repr(client.error)
    assert code == 0, out
    channel = client.advertised["/rosout"]
    assert (channel["schemaName"], channel["encoding"], channel["schemaEncoding"]) == \
        ("foxglove.Log", "json", "jsonschema")
    own = [(log["level"], log["name"], log["message"]) for log in client.logs if log["name"] == "P"]
    assert own == [(1, "P", "debug from P"), (2, "P", "planning 2 items"), (3, "P", "battery low"),
                   (4, "P", "lidar lost"), (5, "P", "safety stop")], out
    assert all(log["timestamp"]["sec"] > 1_700_000_000 and log["file"].endswith("logging_roles.py")
               for log in client.logs)
    assert "foxglove: 6 log records on /rosout (foxglove.Log)" in out
