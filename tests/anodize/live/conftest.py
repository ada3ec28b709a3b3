"""What the live view's end-to-end tests share: a run that waits for its test client.

A test's Foxglove client connects from a thread of its own while ``anodize run`` starts.
Left to the scheduler, the groups may start (and the pad's run end) before the client has
subscribed, so what the client sees would depend on how busy the machine is: a client that
subscribes late gets only the flood of the groups' messages, not the statuses before it.
:func:`run_waits_for_client` makes the order part of the test: the groups start only once
the client listens on the status topic.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pytest

from anodize import _live as live
from anodize._live import STATUS_TOPIC

SUBSCRIBE_WITHIN = 30.0  # seconds the run waits for the client; then it starts anyway (and the test says so)


@dataclass
class HeldRun:
    """The live views ``anodize run`` opened, and whether a client had subscribed when each run began."""

    views: list[Any] = field(default_factory=list)
    subscribed: list[bool] = field(default_factory=list)


@pytest.fixture
def run_waits_for_client(monkeypatch: pytest.MonkeyPatch) -> HeldRun:
    """``anodize run --foxglove`` whose groups start only once a client subscribes to the status topic."""
    held = HeldRun()
    opened = live.open_live_view

    def open_view(port: int = live.DEFAULT_PORT, host: str = "127.0.0.1") -> Any:
        view = opened(port, host)
        begin = view.begin

        def begin_when_subscribed(run: Any) -> Any:
            plan = begin(run)  # the channels are advertised: the client can subscribe now
            held.subscribed.append(_within(SUBSCRIBE_WITHIN, lambda: any(
                STATUS_TOPIC in topics for topics in list(view.clients.values()))))
            return plan

        view.begin = begin_when_subscribed
        held.views.append(view)
        return view

    monkeypatch.setattr(live, "open_live_view", open_view)
    return held


def _within(seconds: float, condition: Callable[[], bool]) -> bool:
    """Whether ``condition()`` came true within ``seconds`` (polled)."""
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.01)
    return True
