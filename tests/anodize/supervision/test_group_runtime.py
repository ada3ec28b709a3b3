"""How a group's process runs Python.

- It freezes what its start made before its roles run, so no garbage collection in a role's
  thread scans the modules, classes and endpoints again (a full collection holds the GIL
  throughout: 11-18 ms with TinMan's role modules imported, more than its joystick may slip;
  decision 0066).
- A real-time group lets a thread keep the GIL 1 ms, not Python's 5 ms, while another waits for
  it (decision 0067).
"""

from __future__ import annotations

import os

import pytest
import runtime_roles

import anodize
import sessiontypes
from anodize._supervision.groupproc import REAL_TIME_SWITCH_INTERVAL

pytestmark = pytest.mark.slow  # group processes

SEEN = sessiontypes.loads(runtime_roles.PROTOCOL, "seen.proto").globals["S"]


def _run(priority: int | None) -> anodize.RunReport:
    system = anodize.System(SEEN, transport=anodize.Processes())
    system.group("a", priority=priority).role("A", runtime_roles.reporter)
    system.group("b").role("B", runtime_roles.checker)
    return system.run(timeout=60)


def test_a_group_process_freezes_its_start_and_keeps_python_s_switch_interval(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("RUNTIME_TEST_SWITCH", str(0.005))
    report = _run(priority=None)
    assert report.ok, report.summary()  # B found A's function frozen, among at least 10,000 objects


def test_a_real_time_group_hands_the_gil_on_sooner(monkeypatch: pytest.MonkeyPatch) -> None:
    if os.environ.get("ANODIZE_NO_RT"):
        pytest.skip("real time is turned off here (ANODIZE_NO_RT)")
    monkeypatch.setenv("RUNTIME_TEST_SWITCH", str(REAL_TIME_SWITCH_INTERVAL))
    report = _run(priority=10)
    if not report.groups["a"].scheduling.startswith("SCHED_FIFO"):
        pytest.skip(f"this machine refused SCHED_FIFO ({report.groups['a'].scheduling}); nothing changes then")
    assert report.ok, report.summary()  # B found A's process frozen and at the shorter interval
