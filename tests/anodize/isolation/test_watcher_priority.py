"""The supervisor's watching thread: raised above ordinary work, not passed on to what it starts."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Callable

import pytest

from anodize._isolation.watchdog import WATCHER_PRIORITY, prioritise_watcher


def in_a_thread(body: Callable[[], None]) -> None:
    """Run ``body`` in a fresh thread (the scheduling it changes is that thread's), re-raising."""
    failures: list[BaseException] = []

    def run() -> None:
        try:
            body()
        except BaseException as error:  # re-raised in the test's thread
            failures.append(error)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join(30)
    if failures:
        raise failures[0]


def test_the_watcher_runs_at_fifo_1_and_what_it_starts_does_not(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ANODIZE_NO_RT", raising=False)

    def body() -> None:
        before = os.sched_getscheduler(0)
        described, restore = prioritise_watcher()
        if described.startswith("SCHED_OTHER (SCHED_FIFO refused"):  # unprivileged: said so, nothing changed
            assert os.sched_getscheduler(0) == before
            return
        assert described == f"SCHED_FIFO {WATCHER_PRIORITY}"
        assert os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK == os.SCHED_FIFO
        child = subprocess.run([sys.executable, "-c", "import os; print(os.sched_getscheduler(0))"],
                               capture_output=True, text=True, check=True)
        assert int(child.stdout) == os.SCHED_OTHER  # reset on fork: a group keeps its own scheduling
        seen: list[int] = []
        helper = threading.Thread(target=lambda: seen.append(os.sched_getscheduler(0)))
        helper.start()
        helper.join()
        assert seen == [os.SCHED_OTHER]
        restore()
        assert os.sched_getscheduler(0) == before

    in_a_thread(body)


def test_anodize_no_rt_leaves_the_watcher_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ANODIZE_NO_RT", "1")

    def body() -> None:
        before = os.sched_getscheduler(0)
        described, restore = prioritise_watcher()
        assert "ANODIZE_NO_RT" in described and os.sched_getscheduler(0) == before
        restore()

    in_a_thread(body)
