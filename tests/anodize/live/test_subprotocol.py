"""A client offering another WebSocket subprotocol than the live view's gets one clear answer.

The SDK's server accepts only ``foxglove.sdk.v1`` and drops anything else with "handshake
failed", logged at each of a client's retries. In front of it, the gate answers HTTP 400
naming the subprotocol, the run's output gets one line per client, and the report counts
the attempts; a client that offers the right subprotocol still reaches the SDK.
"""

from __future__ import annotations

import asyncio
import logging
import socket
from typing import Any

import pytest

from anodize._live import open_live_view
from anodize._live.gate import SUBPROTOCOL, Handshake, parse_head, refusal

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")

OLD = "foxglove.websocket.v1"


async def _handshake(port: int, offered: list[str] | None) -> tuple[int, str]:
    """(101 and the agreed subprotocol) or (the HTTP status and body of the refusal)."""
    try:
        async with asyncio.timeout(10.0):
            async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=offered) as ws:
                first = await ws.recv()
                assert '"op":"serverInfo"' in str(first)
                return 101, str(ws.subprotocol)
    except websockets.InvalidStatus as refused:
        response: Any = refused.response
        return int(response.status_code), bytes(response.body).decode()


def test_parse_head_reads_the_offer_in_any_case() -> None:
    head = (b"GET / HTTP/1.1\r\nHost: x\r\nupgrade: WebSocket\r\n"
            b"SEC-WEBSOCKET-PROTOCOL: a.v1, foxglove.sdk.v1\r\n\r\n")
    assert parse_head(head) == Handshake(True, ("a.v1", SUBPROTOCOL))
    assert parse_head(head).accepted
    assert not parse_head(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n").accepted
    answer = refusal(Handshake(True, (OLD,))).decode()
    assert answer.startswith("HTTP/1.1 400 Bad Request\r\n")
    assert f"speaks the WebSocket subprotocol {SUBPROTOCOL}" in answer
    assert f"offered the WebSocket subprotocol {OLD}" in answer


def test_another_subprotocol_is_refused_by_name_once_per_client(caplog: pytest.LogCaptureFixture) -> None:
    view = open_live_view(0)
    try:
        with caplog.at_level(logging.DEBUG):
            answers = [asyncio.run(_handshake(view.port, [OLD])) for _ in range(3)]
            bare = asyncio.run(_handshake(view.port, None))
            accepted = asyncio.run(_handshake(view.port, [OLD, SUBPROTOCOL]))
    finally:
        view.close()
    for status, body in [*answers, bare]:
        assert status == 400
        assert f"It speaks the WebSocket subprotocol {SUBPROTOCOL}" in body
    assert f"offered the WebSocket subprotocol {OLD}" in answers[0][1]
    assert "offered no WebSocket subprotocol" in bare[1]
    assert accepted == (101, SUBPROTOCOL)  # the SDK behind the gate, reached unchanged
    shown = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert shown == [(f"foxglove: refused a client at 127.0.0.1: it offered the WebSocket subprotocol {OLD}, and "
                      f"this live view speaks {SUBPROTOCOL} only (answered HTTP 400; its further attempts are counted "
                      "in the report)")]
    assert view.refusals == {("127.0.0.1", (OLD,)): 3, ("127.0.0.1", ()): 1}


def test_a_client_that_sends_no_request_is_let_go() -> None:
    view = open_live_view(0)
    try:
        with socket.create_connection(("127.0.0.1", view.port), timeout=10.0) as quiet:
            quiet.sendall(b"GET / HTTP/1.1\r\n")  # and never the blank line
            quiet.settimeout(10.0)
            assert quiet.recv(100) == b""  # closed by the gate after its wait, without an answer
        assert asyncio.run(_handshake(view.port, [SUBPROTOCOL])) == (101, SUBPROTOCOL)
    finally:
        view.close()
