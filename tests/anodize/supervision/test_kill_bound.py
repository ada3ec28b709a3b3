"""Every wait for a group is bounded: a group that does not end when killed (a process stuck in
the kernel, a runner that lost it) is given up on, and the run still returns (issue 27 item 10)."""

from __future__ import annotations

import time
from collections.abc import Sequence

import pytest

from anodize._supervision import supervisor
from anodize._supervision.events import Event, Ready
from anodize._supervision.group import Group
from anodize._supervision.report import RoleStatus
from anodize._supervision.supervisor import Supervisor

LOOKS = 2000  # at 10 ms a look: the bound of this test's own wait


class Undying:
    """A runner whose one group never ends: stop and kill are both ignored."""

    transport = "fake"

    def __init__(self) -> None:
        self.pending: list[Event] = []
        self.looks = 0
        self.killed = 0

    def start(self, groups: Sequence[str], incarnation: int) -> None:
        self.pending += [Ready(group=name, incarnation=incarnation) for name in groups]

    def go(self, group: str) -> None:
        pass

    def events(self, timeout: float) -> list[Event]:
        self.looks += 1
        assert self.looks < LOOKS, "the supervisor is still waiting for a group it killed"
        time.sleep(min(timeout, 0.01))
        events, self.pending = self.pending, []
        return events

    def tell_failed(self, group: str, role: str, cause: str) -> None:
        pass

    def stop(self, group: str) -> None:
        pass

    def kill(self, group: str) -> None:
        self.killed += 1

    def notes(self) -> list[str]:
        return []

    def bound(self, seconds: float) -> None:
        pass

    def close(self) -> None:
        pass


def test_a_killed_group_that_never_ends_is_given_up_on(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(supervisor, "KILL_BOUND", 0.2, raising=False)
    runner = Undying()
    group = Group("a", roles={"A": "m:f"})
    report = Supervisor("P", ["A"], {"a": group}, [], runner, 0.05, 0.05, None).run()  # type: ignore[arg-type]
    assert runner.killed == 1
    role = report.roles["A"]
    assert role.status is RoleStatus.STOPPED
    assert "did not end within 0.2 s of being killed" in role.detail, role
