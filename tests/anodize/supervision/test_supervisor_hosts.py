"""The supervisor's side of policies across hosts, driven by a scripted runner and link
(no processes, no DDS): what it says, what it does on what it hears, in every order."""

from __future__ import annotations

import os
import time
from collections import deque
from collections.abc import Sequence

import pytest
from hypothesis import given
from hypothesis import strategies as st

from anodize._supervision.events import Event, GroupExited, Ready, RoleEnded
from anodize._supervision.group import FailurePolicy, Group
from anodize._supervision.hostview import HELLO_EVERY, HostView
from anodize._supervision.report import GroupState, RoleReport, RoleStatus
from anodize._supervision.runner import Elsewhere
from anodize._supervision.supervisor import Supervisor
from anodize._supervision.words import Decision, HelloWord, RestartWord, StopWord, Word
from anodize.errors import PeerFailedError, RoleError

HERE = "B"


class Script:
    """Runner and link in one: each step of the script is what one look returns."""

    transport = "fake"
    host = HERE
    supervisor = "b0b0"

    def __init__(self, steps: Sequence[list[Event] | list[Word]]) -> None:
        self.steps = deque(steps)
        self.pending: list[Event] = []
        self.dying: list[Event] = []  # a killed group's exit comes a look later, as a process's does
        self.incarnation: dict[str, int] = {}
        self.started: list[tuple[list[str], int]] = []
        self.stopped: list[str] = []
        self.said: list[Word] = []  # but hellos
        self.hellos: list[HelloWord] = []

    # ---- Runner ----
    def start(self, groups: Sequence[str], incarnation: int) -> None:
        self.started.append((list(groups), incarnation))
        for name in groups:
            self.incarnation[name] = incarnation
            self.pending.append(Ready(group=name, incarnation=incarnation))

    def go(self, group: str) -> None:
        pass

    def events(self, timeout: float) -> list[Event]:
        time.sleep(0.002)  # a look takes a little time, as a runner's does (hellos are due by the clock)
        events, self.pending, self.dying = self.pending, self.dying, []
        if self.steps and (not self.steps[0] or not isinstance(self.steps[0][0], StopWord | RestartWord | HelloWord)):
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
        if isinstance(word, HelloWord):
            self.hellos.append(word)
        else:
            self.said.append(word)

    def words(self) -> list[Word]:
        if self.steps and self.steps[0] and isinstance(self.steps[0][0], StopWord | RestartWord | HelloWord):
            return self.steps.popleft()  # type: ignore[return-value]
        return []


def supervise(script: Script, local: dict[str, Group], remote: dict[str, Group],
              channels: tuple[tuple[str, str], ...], lost_after: float = 3.0, linger: float = 10.0) -> Supervisor:
    everyone = {**local, **remote}
    group_of = {role: g.name for g in everyone.values() for role in g.roles}
    local_channels = tuple(c for c in channels if group_of[c[0]] in local and group_of[c[1]] in local)
    roles = [role for g in local.values() for role in g.roles]
    # A timeout, so that a script that leaves a group running ends (its assertions then fail).
    return Supervisor("P", roles, local, local_channels, script, 5.0, 1.0, None,  # type: ignore[arg-type]
                      Elsewhere(script, everyone, channels, lost_after, linger))


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


# ---- hellos: split brain, words missed while cut off, a host lost and back -------------------
SAID: dict[str, int] = {}  # per supervisor, the hellos made so far in this test (numbered as a supervisor does)


@pytest.fixture(autouse=True)
def _numbering_afresh() -> None:
    SAID.clear()


def hello(groups: dict[str, int], supervisor: str = "a1", host: str = "A", **fields: object) -> HelloWord:
    """A hello of ``supervisor``, numbered after its last one unless ``number`` is given."""
    if "number" not in fields:
        fields["number"] = SAID.get(supervisor, -1) + 1
    SAID[supervisor] = max(SAID.get(supervisor, -1), int(fields["number"]))  # type: ignore[call-overload]
    return HelloWord(host, 4242, groups, supervisor=supervisor, **fields)  # type: ignore[arg-type]


CONSUMING = group("consuming", "C", FailurePolicy.STOP)


def test_hellos_say_who_this_supervisor_is_and_what_it_runs() -> None:
    script = Script([[], [], done("consuming", "C", 0)])
    supervise(script, {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS).run()
    first = script.hellos[0]
    assert (first.host, first.supervisor, first.pid, first.groups, first.state) == (
        HERE, "b0b0", os.getpid(), {"consuming": 0}, "running")
    assert script.hellos[-1].state == "ended"  # its farewell: it leaves, it is not lost
    assert [h.number for h in script.hellos] == list(range(len(script.hellos)))  # a gap would mean a cut


def test_a_second_supervisor_claiming_our_group_stops_the_run_naming_both() -> None:
    script = Script([[], [hello({"consuming": 0}, host=HERE)]])
    report = supervise(script, {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS, linger=0.1).run()
    said = (f"split brain: group consuming claimed by two supervisors, host B (supervisor b0b0, pid {os.getpid()}: "
            "this one) and host B (supervisor a1, pid 4242) (is `anodize run --host B` running twice, or do two "
            "system files place a group differently?); neither can be trusted to be the one its peers met, so "
            "every group of the run stops")
    assert [(type(w), w.why) for w in script.said] == [(StopWord, said)]  # type: ignore[union-attr]
    assert script.stopped == ["consuming"]
    assert report.groups["consuming"].status is GroupState.FAILED
    assert str(report.groups["consuming"].error) == f"SplitBrain: {said}"
    assert f"stopping every group: {said}" in report.notes


def test_two_other_supervisors_claiming_one_group_stop_the_run_here_too() -> None:
    script = Script([[], [hello({"producing": 0})], [hello({"producing": 0}, supervisor="a2")]])
    report = supervise(script, {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS, linger=0.1).run()
    assert script.stopped == ["consuming"]
    assert any(note.startswith("stopping every group: split brain: group producing claimed by two supervisors, "
                               "host A (supervisor a1, pid 4242) and host A (supervisor a2, pid 4242)")
               for note in report.notes), report.notes
    assert report.groups["consuming"].status is GroupState.STOPPED  # not a claimant: stopped, not failed


def test_a_supervisor_restarted_on_its_host_is_no_second_claimant() -> None:
    view = HostView("B", os.getpid(), "b0b0")
    view.hear(hello({"producing": 0}, supervisor="a1"), time.monotonic() - 5 * HELLO_EVERY)  # then killed
    assert view.split(hello({"producing": 0}, supervisor="a2"), {"consuming": 0}) is None  # its successor
    view.hear(hello({"producing": 0}, supervisor="a1"), time.monotonic())  # but if the first one speaks on
    split = view.split(hello({"producing": 0}, supervisor="a2"), {"consuming": 0})
    assert split is not None and split[1] == {"producing"}


def test_two_endpoints_claiming_a_peer_at_the_barrier_stop_the_run_whatever_the_policy() -> None:
    # The channel level agrees with the supervisors: a restart would meet both claimants again.
    error = RoleError("SplitBrainError", "2 DDS endpoints on P->C claim to be group producing on host A: ...")
    ended = RoleEnded(group="consuming", incarnation=0,
                      report=RoleReport(name="C", group="consuming", status=RoleStatus.FAILED, error=error))
    script = Script([[], [ended]])
    supervise(script, {"consuming": group("consuming", "C", FailurePolicy.RESTART)},
              {"producing": PRODUCING}, CHANNELS).run()
    assert [type(w) for w in script.said] == [StopWord]
    assert "split brain" in script.said[0].why  # type: ignore[union-attr]
    assert script.started == [(["consuming"], 0)]  # never restarted


def test_a_restart_said_while_we_were_cut_off_is_heard_again_in_a_hello() -> None:
    decided = Decision(1, ("consuming", "producing"), "role P: PeerFailedError: ...", "A")
    script = Script([[], [hello({"producing": 1}, restarts=(decided,))], [], [], [], done("consuming", "C", 1)])
    report = supervise(script, {"consuming": group("consuming", "C", FailurePolicy.RESTART)},
                       {"producing": PRODUCING}, CHANNELS).run()
    assert script.started == [(["consuming"], 0), (["consuming"], 1)]
    assert report.groups["consuming"].restarts == 1
    assert any("decided on host A" in note for note in report.groups["consuming"].notes)


def test_a_stop_said_while_we_were_cut_off_is_heard_again_in_a_hello() -> None:
    why = "group producing failed and its policy is stop-system"
    script = Script([[], [hello({"producing": 0}, state="stopping", why=why)]])
    report = supervise(script, {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS).run()
    assert script.stopped == ["consuming"]
    assert f"stopping every group: {why} (on host A)" in report.notes
    assert script.said == []  # heard, not said again


SILENCE: list[list[Event] | list[Word]] = [[]] * 300  # about 0.6 s without a word (a look takes 2 ms)


def test_a_host_back_from_a_cut_that_moved_on_without_us_stops_our_groups_that_met_its_own() -> None:
    before = hello({"producing": 0})
    moved_on = hello({"producing": 0}, gone={HERE: {"consuming": 0, "ticking": 0}})
    script = Script([[], [before], *SILENCE, [moved_on], [], [], done("ticking", "Q", 0)])
    report = supervise(script, {"consuming": CONSUMING, "ticking": group("ticking", "Q", FailurePolicy.STOP)},
                       {"producing": PRODUCING}, CHANNELS, lost_after=0.3).run()
    assert script.stopped == ["consuming"]  # ticking has no channel to host A's groups: it runs on
    assert report.groups["consuming"].status is GroupState.STOPPED
    assert report.groups["ticking"].status is GroupState.DONE
    assert ("host A lost sight of this host (cut off?) and moved on without it: stopping consuming, whose "
            "sessions with groups there are over") in report.notes


def test_a_host_first_heard_saying_it_moved_on_without_us_is_obeyed() -> None:
    # Cut off before its first hello reached us (seen: a cut just after the start barrier), we had
    # no hello of it to lose; its first one says it lost us: our sessions with it are over.
    moved_on = hello({"producing": 0}, gone={HERE: {"consuming": 0}})
    script = Script([[], [moved_on], [], [], done("consuming", "C", 0)])
    report = supervise(script, {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS).run()
    assert script.stopped == ["consuming"]
    assert ("host A lost sight of this host (cut off?) and moved on without it: stopping consuming, whose "
            "sessions with groups there are over") in report.notes


def test_a_host_that_only_we_lost_is_not_obeyed_when_it_says_it_moved_on() -> None:
    # Its supervisor lost sight of us, we did not lose it: it was slow to speak (held up starting
    # a process, on a busy machine), not cut off; what it wrote off is still ours to run.
    before = hello({"producing": 0})
    moved_on = hello({"producing": 0}, gone={HERE: {"consuming": 0}})  # the very next: nothing missed
    script = Script([[], [before], [moved_on], [], [], done("consuming", "C", 0)])
    report = supervise(script, {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS).run()
    assert script.stopped == []
    assert report.groups["consuming"].status is GroupState.DONE


def test_a_hello_said_before_the_cut_and_delivered_after_it_does_not_hide_the_cut() -> None:
    # Seen over Zenoh: cut off before any hello reached us, then, once back, a hello said before
    # the cut (it does not say it lost us) and at once the ones said after it (it does); the numbers
    # skipped between them are the cut.
    before = hello({"producing": 0}, number=1)
    moved_on = hello({"producing": 0}, gone={HERE: {"consuming": 0}}, number=13)
    script = Script([[], [before, moved_on], [], [], done("consuming", "C", 0)])
    report = supervise(script, {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS).run()
    assert script.stopped == ["consuming"]
    assert ("host A lost sight of this host (cut off?) and moved on without it: stopping consuming, whose "
            "sessions with groups there are over") in report.notes


def test_a_supervisor_held_up_that_missed_no_hello_does_not_obey_one_that_lost_it() -> None:
    # Held up from its start (a busy machine), it takes its first hellos of A at once, every one
    # of them: A lost it (it was slow to speak), but nothing was lost on the way: no cut.
    hellos = [hello({"producing": 0}, number=n) for n in range(8)]
    hellos.append(hello({"producing": 0}, gone={HERE: {"consuming": 0}}, number=8))
    script = Script([[], hellos, [], [], done("consuming", "C", 0)])
    report = supervise(script, {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS).run()
    assert script.stopped == []
    assert report.groups["consuming"].status is GroupState.DONE


@given(st.lists(st.integers(min_value=0, max_value=40), min_size=1, max_size=30))
def test_hellos_were_missed_lately_exactly_when_their_numbers_skip(numbers: list[int]) -> None:
    # A repeat or a replay of an older hello (a number not above the last taken) is stale: taken for nothing.
    view = HostView("B", os.getpid(), "b0b0", lost_after=60.0)
    now = time.monotonic()
    view.hear(hello({"producing": 0}, number=numbers[0]), now)
    last, skipped = numbers[0], False
    for number in numbers[1:]:
        assert view.stale(hello({"producing": 0}, number=number)) == (number <= last)
        view.hear(hello({"producing": 0}, number=number), now)
        if number > last:
            skipped |= number > last + 1
            last = number
    assert view.missed_lately("a1", now) == skipped
    assert not view.missed_lately("a1", now + 61.0)  # lately: within lost_after
    assert not view.missed_lately("someone else", now)


def test_a_replayed_hello_is_not_taken_and_fakes_no_gap() -> None:
    # Hellos 0..9 heard, then a copy of an old one (number 3), then hello 10, which says A lost us
    # (we were slow to speak). Had the copy been taken, 3 -> 10 would look like hellos lost on the
    # way, a cut, and A's word would stop our group; nothing was lost: it runs on.
    hellos = [hello({"producing": 0}, number=n) for n in range(10)]
    replayed = hello({"producing": 0}, number=3)
    moved_on = hello({"producing": 0}, gone={HERE: {"consuming": 0}}, number=10)
    script = Script([[], hellos, [replayed], [moved_on], [], done("consuming", "C", 0)])
    report = supervise(script, {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS).run()
    assert script.stopped == []
    assert report.groups["consuming"].status is GroupState.DONE


def test_a_silent_host_is_lost_then_back() -> None:
    steps: list[list[Event] | list[Word]] = [[], [hello({"producing": 0})], *SILENCE]
    steps += [[hello({"producing": 0})], [], done("consuming", "C", 0)]
    report = supervise(Script(steps), {"consuming": CONSUMING}, {"producing": PRODUCING}, CHANNELS,
                       lost_after=0.3).run()
    lost = [n for n in report.notes if n.startswith("lost sight of host A at ")]
    assert len(lost) == 1 and lost[0].endswith("(no word from its supervisor for 0.3 s): the run moves on without it")
    assert any(n.startswith("host A is back (its supervisor a1 heard again after ") for n in report.notes)


def test_a_supervisor_that_stopped_the_run_waits_a_bounded_time_for_the_others_to_stop_too() -> None:
    failing = group("consuming", "C", FailurePolicy.STOP_SYSTEM)
    script = Script([[], [hello({"producing": 0})], [failed("consuming", "C", 0)]])
    report = supervise(script, {"consuming": failing}, {"producing": PRODUCING}, CHANNELS, linger=0.3).run()
    assert ("the run stopped while host A did not answer; it did not say it stopped within 0.3 s"
            in report.notes), report.notes
    assert script.hellos[-1].state == "ended" and "stop-system" in script.hellos[-1].why

    answered = Script([[], [hello({"producing": 0})], [failed("consuming", "C", 0)],
                       [hello({"producing": 0}, state="stopping", why="...")]])
    report = supervise(answered, {"consuming": failing}, {"producing": PRODUCING}, CHANNELS, linger=30).run()
    assert not any("did not answer" in note for note in report.notes), report.notes
