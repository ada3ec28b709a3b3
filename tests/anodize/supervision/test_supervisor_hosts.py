"""The supervisor's side of policies across hosts, driven by a scripted runner and link
(no processes, no DDS): what it says, what it does on what it hears, in every order."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

from anodize._supervision.group import FailurePolicy, Group
from anodize._supervision.report import GroupState, RoleReport, RoleStatus
from anodize._supervision.supervisor import (
    Elsewhere,
    Event,
    GroupExited,
    Ready,
    RestartWord,
    RoleEnded,
    StopWord,
    Supervisor,
    Word,
)
from anodize.errors import PeerFailedError

HERE = "B"


class Script:
    """Runner and link in one: each step of the script is what one look returns."""

    transport = "fake"
    host = HERE

    def __init__(self, steps: Sequence[list[Event] | list[Word]]) -> None:
        self.steps = deque(steps)
        self.pending: list[Event] = []
        self.dying: list[Event] = []  # a killed group's exit comes a look later, as a process's does
        self.incarnation: dict[str, int] = {}
        self.started: list[tuple[list[str], int]] = []
        self.stopped: list[str] = []
        self.said: list[Word] = []

    # ---- Runner ----
    def start(self, groups: Sequence[str], incarnation: int) -> None:
        self.started.append((list(groups), incarnation))
        for name in groups:
            self.incarnation[name] = incarnation
            self.pending.append(Ready(group=name, incarnation=incarnation))

    def go(self, group: str) -> None:
        pass

    def events(self, timeout: float) -> list[Event]:
        events, self.pending, self.dying = self.pending, self.dying, []
        if self.steps and (not self.steps[0] or not isinstance(self.steps[0][0], StopWord | RestartWord)):
            events += self.steps.popleft()  # type: ignore[arg-type]
        return events

    def tell_failed(self, group: str, role: str, cause: str) -> None:
        pass

    def stop(self, group: str) -> None:
        self.stopped.append(group)
        self.pending.append(GroupExited(group=group, incarnation=self.incarnation[group]))

    def kill(self, group: str) -> None:
        self.dying.append(GroupExited(group=group, incarnation=self.incarnation[group]))

    def notes(self) -> list[str]:
        return []

    def bound(self, seconds: float) -> None:
        pass

    def close(self) -> None:
        pass

    # ---- Link ----
    def say(self, word: Word) -> None:
        self.said.append(word)

    def words(self) -> list[Word]:
        if self.steps and self.steps[0] and isinstance(self.steps[0][0], StopWord | RestartWord):
            return self.steps.popleft()  # type: ignore[return-value]
        return []


def supervise(script: Script, local: dict[str, Group], remote: dict[str, Group],
              channels: tuple[tuple[str, str], ...]) -> Supervisor:
    everyone = {**local, **remote}
    group_of = {role: g.name for g in everyone.values() for role in g.roles}
    local_channels = tuple(c for c in channels if group_of[c[0]] in local and group_of[c[1]] in local)
    roles = [role for g in local.values() for role in g.roles]
    # A timeout, so that a script that leaves a group running ends (its assertions then fail).
    return Supervisor("P", roles, local, local_channels, script, 5.0, 1.0, None,  # type: ignore[arg-type]
                      Elsewhere(script, everyone, channels))


def group(name: str, role: str, policy: FailurePolicy, max_restarts: int = 1, host: str = HERE) -> Group:
    return Group(name, on_failure=policy, max_restarts=max_restarts, host=host, roles={role: "m:f"})


def failed(name: str, role: str, incarnation: int) -> RoleEnded:
    error = PeerFailedError(role, "P", "group producing on host A ended")
    return RoleEnded(group=name, incarnation=incarnation,
                     report=RoleReport(name=role, group=name, status=RoleStatus.FAILED, error=error))


def done(name: str, role: str, incarnation: int) -> list[Event]:
    return [RoleEnded(group=name, incarnation=incarnation,
                      report=RoleReport(name=role, group=name, status=RoleStatus.DONE)),
            GroupExited(group=name, incarnation=incarnation)]


CHANNELS = (("P", "C"),)
PRODUCING = group("producing", "P", FailurePolicy.RESTART, host="A")


def test_a_restart_decided_here_names_the_set_across_hosts_and_its_incarnation() -> None:
    script = Script([[], [failed("consuming", "C", 0)], [], [], [], done("consuming", "C", 1)])
    supervisor = supervise(script, {"consuming": group("consuming", "C", FailurePolicy.RESTART)},
                           {"producing": PRODUCING}, CHANNELS)
    report = supervisor.run()
    assert [(w.host, w.groups, w.incarnation) for w in script.said  # type: ignore[union-attr]
            ] == [(HERE, ("consuming", "producing"), 1)]
    assert script.started == [(["consuming"], 0), (["consuming"], 1)]
    assert report.groups["consuming"].restarts == 1
    assert report.groups["consuming"].status is GroupState.DONE


def test_a_restart_heard_before_our_own_failure_is_the_only_one() -> None:
    # Host A restarts {producing, consuming} as incarnation 1; our consumer then fails
    # (its producer is gone): that failure belongs to the restart under way.
    word = RestartWord("A", ("consuming", "producing"), 1, "role P: RuntimeError")
    script = Script([[], [word], [failed("consuming", "C", 0)], [], [], [], done("consuming", "C", 1)])
    supervisor = supervise(script, {"consuming": group("consuming", "C", FailurePolicy.RESTART)},
                           {"producing": PRODUCING}, CHANNELS)
    report = supervisor.run()
    assert script.said == []
    assert script.started == [(["consuming"], 0), (["consuming"], 1)]
    assert report.groups["consuming"].restarts == 1
    assert any("decided on host A" in note for note in report.groups["consuming"].notes)


def test_a_restart_heard_after_we_decided_the_same_one_is_not_done_twice() -> None:
    word = RestartWord("A", ("consuming", "producing"), 1, "role P: RuntimeError")
    script = Script([[], [failed("consuming", "C", 0)], [word], [], [], [], done("consuming", "C", 1)])
    supervisor = supervise(script, {"consuming": group("consuming", "C", FailurePolicy.RESTART)},
                           {"producing": PRODUCING}, CHANNELS)
    report = supervisor.run()
    assert script.started == [(["consuming"], 0), (["consuming"], 1)]
    assert report.groups["consuming"].restarts == 1


def test_a_group_whose_policy_is_not_restart_is_left_out_of_a_remote_set() -> None:
    script = Script([[], [failed("consuming", "C", 0)], [], [], [], done("consuming", "C", 1)])
    supervisor = supervise(script, {"consuming": group("consuming", "C", FailurePolicy.RESTART)},
                           {"producing": group("producing", "P", FailurePolicy.STOP, host="A")}, CHANNELS)
    supervisor.run()
    restarts = [w for w in script.said if isinstance(w, RestartWord)]
    assert [(w.groups, w.incarnation) for w in restarts] == [(("consuming",), 1)]


def test_stop_system_here_is_said_and_a_stop_heard_stops_every_group_here() -> None:
    script = Script([[], [failed("consuming", "C", 0)]])
    supervise(script, {"consuming": group("consuming", "C", FailurePolicy.STOP_SYSTEM)},
              {"producing": PRODUCING}, CHANNELS).run()
    assert [type(w) for w in script.said] == [StopWord]
    assert "stop-system" in script.said[0].why

    heard = Script([[], [StopWord("A", "group producing failed and its policy is stop-system")]])
    report = supervise(heard, {"consuming": group("consuming", "C", FailurePolicy.STOP),
                               "ticking": group("ticking", "Q", FailurePolicy.STOP)},
                       {"producing": PRODUCING}, CHANNELS).run()
    assert sorted(heard.stopped) == ["consuming", "ticking"]
    assert heard.said == []  # a stop heard is not said again
    assert "stopping every group: group producing failed and its policy is stop-system (on host A)" in report.notes
