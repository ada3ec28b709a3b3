"""Agreement of the live monitor, the written semantics and ``verify`` on random constrained
protocols (issue 29's quality bar; timed-spec.md, "Meaning").

Protocols come from ``global_protocols(constrained=True)``, their deadlines made generous (at
least 30 s: a random run keeps no deadline of nanoseconds; time is judged by the last tests here
on purpose). Drivers pick payloads that usually satisfy each message's refinement and sometimes
break it; the executable reference is ``sessiontypes.refine.compile_predicate``. The live
monitor refuses exactly the payloads the reference refuses, blamed on the sender, and nothing is
delivered after; ``verify`` on the recording of the same run agrees (where the live run refused,
the recording ends before it), and on the recording of an unmonitored run it blames exactly the
first payload the reference refuses on each channel.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import pytest
from budget import examples
from hypothesis import HealthCheck, assume, event, given, note, settings
from hypothesis import strategies as st

_STRATEGIES = str(Path(__file__).resolve().parents[2] / "sessiontypes")  # a helper module, no package
if _STRATEGIES not in sys.path:
    sys.path.insert(0, _STRATEGIES)

from refined_drivers import (  # noqa: E402
    ATTEMPTS,
    PROTOCOL_VARIABLE,
    SEED_VARIABLE,
    Attempt,
    Channel,
    RefinedDriver,
    agreement_role,
    generous,
    refined,
)
from role_drivers import Recorder, can_always_end, load_global, machines_of  # noqa: E402
from strategies import GeneratedGlobal, global_protocols  # noqa: E402

import anodize  # noqa: E402
from anodize import DeadlineMissedError, PeerFailedError, ProtocolViolationError, Recording, System  # noqa: E402
from anodize._recording.reader import open_recording  # noqa: E402
from anodize._recording.verify import VerifyReport, verify  # noqa: E402
from sessiontypes import GlobalType  # noqa: E402

SETTINGS = settings(deadline=None, max_examples=examples(25),
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.filter_too_much, HealthCheck.function_scoped_fixture])
RUN_TIMEOUT = 20.0


def _generous(generated: GeneratedGlobal, forks: bool = True) -> GlobalType:
    """The generated global with generous deadlines, when some message is refined and every
    role can always end (else rejected)."""
    note(generated.text)
    machines = machines_of(load_global(generated.text))
    assume(all(can_always_end(m) for m in machines.values()))
    assume(any(refined(m) for m in machines.values()))
    assume(forks or not any(m.forks for m in machines.values()))
    return generous(generated.text)


def _system(gt: GlobalType, seed: int, monitored: bool, record: Path | None = None,
            ) -> tuple[anodize.RunReport, Recorder, dict[Channel, list[Attempt]]]:
    recorder = Recorder(gt.roles)
    attempts: dict[Channel, list[Attempt]] = {}
    system = System(gt, monitors=monitored)
    for role, machine in machines_of(gt).items():
        system.group(f"g_{role}").role(role, RefinedDriver(role, machine, recorder, seed, monitored, attempts))
    report = system.run(timeout=RUN_TIMEOUT, taps=[Recording(record)] if record is not None else [])
    note(report.summary())
    note(f"attempts: {attempts}")
    return report, recorder, attempts


def _verify(path: Path, gt: GlobalType) -> VerifyReport:
    with open_recording(path) as recording:
        return verify(recording, gt, machines=machines_of(gt))


def _first_refused(attempts: list[Attempt]) -> int | None:
    return next((i for i, (_, _, verdict) in enumerate(attempts) if verdict is not None), None)


# ---- the live monitor against the reference ------------------------------------------------------

@SETTINGS
@given(global_protocols(max_depth=5, max_nodes=20, constrained=True), st.integers(0, 2**32 - 1))
def test_the_monitor_refuses_exactly_the_payloads_the_reference_refuses_and_verify_agrees(
        tmp_path_factory: pytest.TempPathFactory, generated: GeneratedGlobal, seed: int) -> None:
    gt = _generous(generated, forks=False)
    path = tmp_path_factory.mktemp("agree") / "run.mcap"
    report, recorder, attempts = _system(gt, seed, monitored=True, record=path)
    refusing = {sender for (sender, _), tried in attempts.items() if _first_refused(tried) is not None}
    event("a payload refused" if refusing else "every payload held")
    if not refusing:
        assert report.ok, report.summary()
    for (sender, receiver), tried in attempts.items():
        sent = recorder.sent[sender, receiver]
        first = _first_refused(tried)
        if first is None:  # every payload held: each left unless a peer's failure stopped the run first
            assert [(label, payload) for label, payload, _ in tried[:len(sent)]] == sent
            continue
        # the refused payload did not leave, nothing was tried on the channel after it
        assert [(label, payload) for label, payload, _ in tried[:first]] == sent
        assert len(tried) == first + 1
        label, payload, verdict = tried[first]
        error = report.roles[sender].error
        assert isinstance(error, ProtocolViolationError), report.summary()
        assert not isinstance(error, DeadlineMissedError)
        assert (error.role, error.blame, error.reason) == (sender, sender, f"{verdict} for {label} {payload!r}")
    for channel, received in recorder.received.items():  # nothing delivered but what left
        assert received == recorder.sent[channel][:len(received)]
    # verify judges the recording of the same run as the monitor did: nothing it refused is there
    verdict_offline = _verify(path, gt)
    note(verdict_offline.text())
    assert all(r.violation is None for r in verdict_offline.channels.values()), verdict_offline.text()
    for name, channel_report in verdict_offline.channels.items():
        sender, receiver = name.split("->")
        assert channel_report.messages == len(recorder.sent[sender, receiver]), verdict_offline.text()


@SETTINGS
@given(global_protocols(max_depth=5, max_nodes=20, constrained=True), st.integers(0, 2**32 - 1))
def test_verify_of_an_unmonitored_run_blames_the_first_payload_the_reference_refuses(
        tmp_path_factory: pytest.TempPathFactory, generated: GeneratedGlobal, seed: int) -> None:
    gt = _generous(generated, forks=False)
    path = tmp_path_factory.mktemp("agree") / "run.mcap"
    report, recorder, attempts = _system(gt, seed, monitored=False, record=path)
    assert report.ok, report.summary()  # nothing checks a payload: every one leaves
    expected: dict[str, tuple[int, str, str]] = {}
    for (sender, receiver), tried in attempts.items():
        first = _first_refused(tried)
        if first is not None:
            expected[f"{sender}->{receiver}"] = (first, sender, "refinement")
    event(f"channels with a refused payload: {min(len(expected), 2)}")
    offline = _verify(path, gt)
    note(offline.text())
    found = {name: (r.violation.index, r.violation.blamed, r.violation.kind)
             for name, r in offline.channels.items() if r.violation is not None}
    assert found == expected, offline.text()
    # every message that left is there; a channel is judged up to its first violation
    assert {name: r.messages for name, r in offline.channels.items() if r.messages} == {
        f"{a}->{b}": len(items) if f"{a}->{b}" not in expected else expected[f"{a}->{b}"][0] + 1
        for (a, b), items in recorder.sent.items() if items}, offline.text()
    for name, (index, _, _) in expected.items():
        sender, receiver = name.split("->")
        label, payload, verdict = attempts[sender, receiver][index]
        violation = offline.channels[name].violation
        assert violation is not None and violation.reason == f"{verdict} for {label} {payload!r}"


def _by_environment(gt: GlobalType, transport: object, path: Path) -> anodize.RunReport:
    system = System(gt, transport)
    for role in gt.roles:
        system.group(f"g_{role}").role(role, agreement_role)
    report = system.run(timeout=RUN_TIMEOUT, taps=[Recording(path)])
    note(report.summary())
    return report


@pytest.mark.slow
@settings(SETTINGS, max_examples=examples(3))
@given(global_protocols(max_depth=4, max_nodes=12, constrained=True), st.integers(0, 2**32 - 1))
def test_on_processes_the_monitor_refuses_what_the_reference_refuses_blaming_the_sender(
        tmp_path_factory: pytest.TempPathFactory, generated: GeneratedGlobal, seed: int) -> None:
    """The drivers run in other processes: what they tried is not seen here, so the run is
    judged against the same drivers' inproc run (the same seed makes the same choices where
    every receive names its peer): the same roles refused, for the same reasons, the same
    messages recorded, and verify agrees."""
    gt = _generous(generated, forks=False)
    assume(not any(m.waits_on_several() for m in machines_of(gt).values()))
    folder = tmp_path_factory.mktemp("agree")
    saved = {name: os.environ.get(name) for name in (PROTOCOL_VARIABLE, SEED_VARIABLE)}
    os.environ[PROTOCOL_VARIABLE], os.environ[SEED_VARIABLE] = generated.text, str(seed)
    try:
        ATTEMPTS.clear()
        inproc = _by_environment(gt, anodize.Inproc(), folder / "inproc.mcap")
        refusing = {sender for (sender, _), tried in ATTEMPTS.items() if _first_refused(tried) is not None}
        event("a payload refused" if refusing else "every payload held")
        processes = _by_environment(gt, anodize.Processes(), folder / "processes.mcap")
    finally:
        for name, old in saved.items():
            if old is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = old

    def refusals(report: anodize.RunReport) -> dict[str, tuple[str, str]]:
        return {role: (outcome.error.blame, outcome.error.reason) for role, outcome in report.roles.items()
                if isinstance(outcome.error, ProtocolViolationError)}

    assert set(refusals(inproc)) <= refusing and bool(refusals(inproc)) == bool(refusing), inproc.summary()
    if len(refusing) <= 1:  # one role refused: the run goes the same way on both transports
        assert refusals(processes) == refusals(inproc), processes.summary()
        assert processes.ok == inproc.ok == (not refusing), processes.summary()
    for role, (blame, reason) in refusals(processes).items():
        assert blame == role and reason.startswith("refinement {"), processes.summary()
    counts = {}
    for name in ("inproc", "processes"):
        offline = _verify(folder / f"{name}.mcap", gt)
        note(offline.text())
        assert all(r.violation is None for r in offline.channels.values()), offline.text()
        counts[name] = {channel: r.messages for channel, r in offline.channels.items() if r.messages}
    if len(refusing) <= 1:
        assert counts["processes"] == counts["inproc"]


# ---- time: a role late on purpose -------------------------------------------------------------

PING = """
global Ping(A, B) = A -> B : go. B -> A : pong(n: int) within 50ms. end
"""


def _ask(ep: anodize.Endpoint) -> None:
    ep.send("B", "go")
    ep.recv("B")


def _dawdle(ep: anodize.Endpoint) -> None:
    ep.recv("A")
    ep.sleep(0.15)  # three times the deadline
    ep.send("A", "pong", {"n": 1})


def _ping(monitored: bool, record: Path | None = None) -> anodize.RunReport:
    system = System(load_global(PING, "Ping"), monitors=monitored)
    system.group("a").role("A", _ask)
    system.group("b").role("B", _dawdle)
    return system.run(timeout=RUN_TIMEOUT, taps=[Recording(record)] if record is not None else [])


def test_a_late_role_is_blamed_live_and_by_verify_of_an_unmonitored_recording(tmp_path: Path) -> None:
    live = _ping(monitored=True)
    errors: dict[str, Any] = {role: outcome.error for role, outcome in live.roles.items()}
    # A waits for pong until its deadline; on a busy machine its thread may first run after B's own
    # monitor has failed B for the late send: A is then told that B failed, for that deadline.
    # Either way B, and only B, is blamed, for the deadline.
    if isinstance(errors["A"], PeerFailedError):
        assert errors["A"].peer == "B" and "deadline missed" in errors["A"].cause, live.summary()
        errors["A"] = errors["B"]
    assert all(isinstance(error, DeadlineMissedError) for error in errors.values()), live.summary()
    assert {role: (error.blame, error.kind) for role, error in errors.items()} == {
        "A": ("B", "deadline"), "B": ("B", "deadline")}
    path = tmp_path / "run.mcap"
    unmonitored = _ping(monitored=False, record=path)
    assert unmonitored.ok, unmonitored.summary()
    offline = _verify(path, load_global(PING, "Ping"))
    broken = {name: r.violation for name, r in offline.channels.items() if r.violation is not None}
    assert list(broken) == ["B->A"], offline.text()
    violation = broken["B->A"]
    assert (violation.index, violation.blamed, violation.kind) == (0, "B", "deadline"), offline.text()
    assert violation.location == errors["A"].location == errors["B"].location == "generated.proto:2:56"
