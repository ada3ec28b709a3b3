"""Priority inheritance over channels: the boost is applied while a wait blocks and removed
after it, through chains, on timeout and on the waiter's death; off per group; never at or
below the waiter's own priority. Behaviour, not timings: priorities are read from the kernel
(``sched_getparam`` on the target thread's id)."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from pathlib import Path

import inherit_roles as roles
import pytest
from dds_hosts import domain

import anodize
import sessiontypes
from anodize._isolation.inherit import BoostTable, RoleSeat
from anodize._supervision.report import RunReport

ASK = sessiontypes.loads("global Ask(H, L) = mu t. H -> L : {ask. L -> H : answer(nat). t, stop}",
                         "test_inheritance.proto").globals["Ask"]
FLOOD = sessiontypes.loads("global Flood(H, L) = mu t. H -> L : {data(bytes). t, stop}",
                           "test_inheritance_flood.proto").globals["Flood"]
PARALLEL = sessiontypes.loads(
    "global Par(H, L, K) = (H -> L : ask. L -> H : answer(nat). end || K -> L : go. end)",
    "test_inheritance_par.proto").globals["Par"]
EITHER = sessiontypes.loads(
    "global Either(H, L, M) = H -> L : ask. H -> M : ask. "
    "(L -> H : answer(nat). end || M -> H : answer(nat). end)",
    "test_inheritance_either.proto").globals["Either"]
TICKS = sessiontypes.loads(f"global Ticks(H, L) = mu t. H -> L : {{{roles.TICK}. t, stop}}",
                           "test_inheritance_ticks.proto").globals["Ticks"]
CHAIN = sessiontypes.loads(
    "global Chain(H, M, L) = mu t. H -> M : {ask. M -> L : ask. L -> M : answer(nat). "
    "M -> H : answer(nat). t, stop. M -> L : stop}", "test_inheritance_chain.proto").globals["Chain"]


TRANSPORTS = {"inproc": anodize.Inproc, "process": anodize.Processes}


def _fifo_refused() -> str:
    if os.environ.get("ANODIZE_NO_RT"):
        return "ANODIZE_NO_RT is set"
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        os.sched_setscheduler(0, before[0], before[1])
    except (OSError, AttributeError) as error:
        return f"SCHED_FIFO refused here ({error}): inheritance is inactive"
    return ""


pytestmark = pytest.mark.skipif(bool(_fifo_refused()), reason=_fifo_refused() or "-")


@pytest.fixture(autouse=True)
def test_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("ANODIZE_TEST_DIR", str(tmp_path))
    return tmp_path


def _log(tmp_path: Path) -> list[str]:
    return (tmp_path / "log").read_text().splitlines()


def _ask(transport: str, h: int, l_priority: int, inherit: bool = True,
         asker: Callable[[anodize.Endpoint], None] = roles.asker) -> RunReport:
    system = anodize.System(ASK, transport=TRANSPORTS[transport]())
    system.group("high", priority=h, cpus={0}).role("H", asker)
    system.group("low", priority=l_priority, cpus={0}, priority_inheritance=inherit).role("L", roles.answerer)
    return system.run(timeout=30)


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_the_target_runs_at_the_waiters_priority_while_it_waits_and_drops_back(
        transport: str, test_dir: Path) -> None:
    report = _ask(transport, 60, 10)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["during 60 after 10"] * 2
    assert report.boosts["H->L"]["episodes"] == 2
    assert report.boosts["H->L"]["seconds"] > 0
    assert "priority inheritance: H->L 2 boosts" in report.summary()
    assert report.to_dict()["boosts"]["H->L"]["episodes"] == 2
    assert report.inheritance_inactive == ()


def test_where_sched_fifo_was_refused_the_report_says_inheritance_is_inactive(
        test_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ANODIZE_NO_RT", "1")  # every group falls back to a nice value
    report = _ask("inproc", 60, 10)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["during 0 after 0"] * 2
    assert (report.boosts, report.inheritance_inactive) == ({}, ("H", "L"))
    assert "priority inheritance inactive for H, L (no SCHED_FIFO: a nice value was applied instead)" \
        in report.summary()


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_a_message_already_there_is_taken_without_waiting(transport: str, test_dir: Path) -> None:
    system = anodize.System(ASK, transport=TRANSPORTS[transport]())
    system.group("high", priority=60, cpus={0}).role("H", roles.late_asker)
    system.group("low", priority=10, cpus={0}).role("L", roles.prompt_answerer)
    report = system.run(timeout=10)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["answered"]
    assert "H->L" not in report.boosts  # H never blocked on L


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_a_recorded_run_inherits_too(transport: str, test_dir: Path) -> None:
    from anodize._recording import Recording

    system = anodize.System(ASK, transport=TRANSPORTS[transport]())
    system.group("high", priority=60, cpus={0}).role("H", roles.asker)
    system.group("low", priority=10, cpus={0}).role("L", roles.answerer)
    report = system.run(timeout=30, taps=[Recording(test_dir / "run.mcap")])  # every channel tapped
    assert report.ok, report.summary()
    assert _log(test_dir) == ["during 60 after 10"] * 2


def test_turned_off_per_group(test_dir: Path) -> None:
    report = _ask("inproc", 60, 10, inherit=False)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["during 10 after 10"] * 2
    assert "H->L" not in report.boosts


def test_never_applied_at_or_below_the_waiters_own_priority(test_dir: Path) -> None:
    report = _ask("inproc", 10, 40)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["during 40 after 40"] * 2
    assert "H->L" not in report.boosts  # (L, waiting on H's next ask, does lend H its 40)


def test_undone_when_the_wait_times_out(test_dir: Path) -> None:
    report = _ask("inproc", 60, 10, asker=roles.impatient_asker)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["timeout after 10"]


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_through_a_chain(transport: str, test_dir: Path) -> None:
    system = anodize.System(CHAIN, transport=TRANSPORTS[transport]())
    system.group("high", priority=70, cpus={0}).role("H", roles.chain_asker)
    system.group("mid", priority=30, cpus={0}).role("M", roles.middle)
    system.group("low", priority=10, cpus={0}).role("L", roles.chain_answerer)
    report = system.run(timeout=30)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["during 70 after 10"]


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_a_sender_blocked_on_a_full_channel_lends_its_priority(transport: str, test_dir: Path) -> None:
    # between threads a capacity of 1 message; between processes the pipe (1 MiB) fills
    capacities = {"H->L": 1} if transport == "inproc" else None
    system = anodize.System(FLOOD, transport=TRANSPORTS[transport](), capacities=capacities)
    system.group("high", priority=60, cpus={0}).role("H", roles.flooder)
    system.group("low", priority=10, cpus={0}).role("L", roles.slow_sink)
    report = system.run(timeout=30)
    assert report.ok, report.summary()
    assert sorted(_log(test_dir)) == ["after 10", "during 60"]
    assert report.boosts["H->L"]["episodes"] >= 1


def test_small_messages_written_by_the_compiled_writer_lend_when_the_pipe_is_full(test_dir: Path) -> None:
    system = anodize.System(TICKS, transport=anodize.Processes())
    system.group("high", priority=60, cpus={0}).role("H", roles.ticker)
    system.group("low", priority=10, cpus={0}).role("L", roles.tick_sink)
    report = system.run(timeout=60)
    assert report.ok, report.summary()
    assert sorted(_log(test_dir)) == ["after 10", "during 60"]


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_the_thread_of_a_parallel_branch_is_boosted(transport: str, test_dir: Path) -> None:
    system = anodize.System(PARALLEL, transport=TRANSPORTS[transport]())
    system.group("high", priority=60, cpus={0}).role("H", roles.single_asker)
    system.group("low", priority=10, cpus={0}).role("L", roles.branch_answerer)
    system.group("kick", priority=20).role("K", roles.kicker)
    report = system.run(timeout=30)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["during 60"]


def test_a_wait_on_whichever_peer_sends_first_lends_to_each(test_dir: Path) -> None:
    system = anodize.System(EITHER, transport=anodize.Inproc())
    system.group("high", priority=60, cpus={0}).role("H", roles.any_asker)
    system.group("low", priority=10, cpus={0}).role("L", roles.any_answerer)
    system.group("mid", priority=20, cpus={0}).role("M", roles.any_answerer)
    report = system.run(timeout=30)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["L during 60", "M during 60"]


@pytest.mark.slow
def test_dds_groups_on_this_host_inherit_too(test_dir: Path) -> None:
    pytest.importorskip("cyclonedds", reason="the Dds transport needs cyclonedds")
    system = anodize.System(ASK, transport=anodize.Dds(domain=domain(), run_id="inherit", wait=20))
    system.group("high", priority=60, cpus={0}).role("H", roles.asker)
    system.group("low", priority=10, cpus={0}).role("L", roles.answerer)
    report = system.run(timeout=60)
    assert report.ok, report.summary()
    assert _log(test_dir) == ["during 60 after 10"] * 2


@pytest.mark.slow
def test_a_waiter_that_dies_leaves_no_peer_boosted(test_dir: Path) -> None:
    system = anodize.System(ASK, transport=anodize.Processes())
    system.group("high", priority=60, cpus={0}).role("H", roles.dying_asker)
    system.group("low", priority=10, cpus={0}).role("L", roles.watching_answerer)
    system.run(timeout=30)
    assert _log(test_dir) == ["orphan 10"]


class _Player:
    """A thread that plays ``role`` in ``table`` at SCHED_FIFO ``priority``, blocking (never
    spinning) until told to look at its own priority or to end."""

    def __init__(self, table: BoostTable, role: str, priority: int) -> None:
        self.table, self.role, self.priority = table, role, priority
        self.entered, self.look, self.looked, self.end = (threading.Event() for _ in range(4))
        self.seen: list[int] = []
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        assert self.entered.wait(10)

    def _run(self) -> None:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.priority))
        self.table.enter(self.role)
        self.entered.set()
        while not self.end.is_set():
            if self.look.wait(0.05):
                self.look.clear()
                self.seen.append(roles.own_priority())
                self.looked.set()
        self.table.leave(self.role)

    def priority_now(self) -> int:
        self.looked.clear()
        self.look.set()
        assert self.looked.wait(10)
        return self.seen[-1]

    def stop(self) -> None:
        self.end.set()
        self.thread.join(10)


def test_a_restarted_target_runs_at_its_own_priority_unless_a_waiter_still_waits() -> None:
    table = BoostTable.create([RoleSeat("H", 60, True), RoleSeat("L", 10, True)])
    waiter = None
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(60))  # this thread plays H
        try:
            table.enter("H")
            first = _Player(table, "L", 10)
            waiting = table.waiting("H", "L")
            waiting.__enter__()
            waiter = waiting
            assert first.priority_now() == 60
            first.stop()  # the target's incarnation ends while H waits on it
            assert table.applied("L") == 0
            second = _Player(table, "L", 10)  # restarted: H still waits, so it is lent H's priority
            assert second.priority_now() == 60
            waiting.__exit__(None, None, None)
            waiter = None
            assert second.priority_now() == 10
            second.stop()
            third = _Player(table, "L", 10)  # restarted with nobody waiting: its own priority
            assert third.priority_now() == 10
            third.stop()
        finally:
            if waiter is not None:
                waiter.__exit__(None, None, None)
            table.leave("H")
            os.sched_setscheduler(0, before[0], before[1])
    finally:
        table.close()


def test_a_group_the_watchdog_demoted_is_not_boosted_back_up() -> None:
    table = BoostTable.create([RoleSeat("H", 60, True), RoleSeat("L", 10, True)])
    before = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(60))  # this thread plays H
        table.enter("H")
        target = _Player(table, "L", 10)
        try:
            with table.waiting("H", "L"):
                assert target.priority_now() == 60
                tid = target.thread.native_id
                assert tid is not None
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))  # as watchdog.demote does
                table.demote(["L"])
            assert (target.priority_now(), os.sched_getscheduler(tid)) == (0, os.SCHED_OTHER)
            with table.waiting("H", "L"):
                assert target.priority_now() == 0
        finally:
            target.stop()
            table.leave("H")
    finally:
        os.sched_setscheduler(0, before[0], before[1])
        table.close()


def test_the_group_keyword_is_checked() -> None:
    system = anodize.System(ASK, transport=anodize.Inproc())
    with pytest.raises(ValueError, match="priority_inheritance must be True or False, got 'no'"):
        system.group("g", priority_inheritance="no")  # type: ignore[arg-type]
