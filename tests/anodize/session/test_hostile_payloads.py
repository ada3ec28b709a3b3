"""Payloads whose own code attacks the endpoint checking them, and classes that lie about what
they are (issue 27, items 3 and 13), on both endpoint cores.

Item 3: a payload's methods (or the declared sort's class) may run inside ``send`` and
``recv`` and delete or replace the endpoint's attributes; the compiled core crashed there
(SIGSEGV). Each hostile payload runs in a child process, so that a crash is a failed test and
not a dead pytest, and both cores must do the same: finish the call with the fields they read
when it started, then refuse the next with an AnodizeError naming the role and the attribute.
The property test generates the mutations (any attribute of the endpoint, its monitor or its
channels, deleted or replaced) and runs each example in a forked child.

Item 13: what a payload *is* comes from its real type compared by identity: a metaclass whose
``__eq__`` says it is ``int``, a ``__class__`` that says ``int``, an int subclass whose ``__ge__``
says it is not negative, pass neither monitor (payloads.py says the subclass policy both cores
share: exact type at once, real subclasses by the full check).
"""

from __future__ import annotations

import json
import os
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import hostile_payloads
import pytest
from budget import examples
from hostile_payloads import (
    HOOKS,
    ClaimsInt,
    Nameless,
    NegativeInt,
    PosesAsInt,
    PythonEndpoint,
    Record,
    both_cores,
    run_case,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from anodize._session.endpoint import COMPILED_CORE, Endpoint
from anodize._session.monitor import Monitor

needs_compiled = pytest.mark.skipif(COMPILED_CORE is None, reason="the compiled core was not built here")
_HELPERS = Path(hostile_payloads.__file__).resolve().parent
_CHANNELS = {"send": "_out", "recv": "_in"}
_COUNTS = {"send": "sent", "recv": "received"}


def _in_a_child(hook: str, direction: str, plan: list[tuple[str, str, str]]) -> dict[str, Any]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(path for path in sys.path if path)}
    result = subprocess.run([sys.executable, "-m", "hostile_payloads", hook, direction, json.dumps(plan)],
                            cwd=_HELPERS, env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, (f"the child ended with {result.returncode} (negative: killed by that signal; "
                                    f"-11 is SIGSEGV)\n{result.stderr[-3000:]}")
    found: dict[str, Any] = json.loads(result.stdout)
    return found


def _assert_clean(outcomes: list[list[str]]) -> None:
    for outcome in outcomes:
        assert outcome[0] == "returned" or outcome[2] == "anodize", outcome


@needs_compiled
@pytest.mark.parametrize("direction", ["send", "recv"])
@pytest.mark.parametrize("hook", HOOKS)
def test_a_payload_deleting_the_endpoints_fields_gets_the_same_clean_error_from_both_cores(
        hook: str, direction: str) -> None:
    role = "A" if direction == "send" else "B"
    plan = [("endpoint", "_monitor", "delete"), ("endpoint", _CHANNELS[direction], "delete"),
            ("endpoint", _COUNTS[direction], "delete")]
    found = _in_a_child(hook, direction, plan)
    assert found["python"] == found["compiled"]
    assert found["python fired"] == found["compiled fired"]
    _assert_clean(found["python"])
    first, then = found["python"]
    if found["python fired"]:  # the call finished on what it read first; the next one is refused
        assert then[:1] == ["AnodizeError"] and f"role {role}: the endpoint's attribute _monitor is missing" in then[1]
    else:  # a lie the monitors no longer ask about (item 13): nothing ran, the next call goes ahead
        assert first[0] == "ProtocolViolationError" and then[0] == "returned"


@needs_compiled
@pytest.mark.parametrize("direction", ["send", "recv"])
@pytest.mark.parametrize("plan", [
    [("endpoint", "_monitor", "the other endpoint's"), ("endpoint", "_out", "the other endpoint's"),
     ("endpoint", "_in", "the other endpoint's")],
    [("endpoint", "_out", "None"), ("endpoint", "_in", "zero"), ("endpoint", "sent", "text"),
     ("endpoint", "received", "empty list")],
    [("channels", "B", "triple"), ("channels", "A", "object"), ("endpoint", "high_water", "empty dict")],
    [("endpoint", "role", "delete"), ("endpoint", "_network", "delete"), ("endpoint", "_lending", "delete")],
], ids=["swapped", "junk", "junk channels", "role deleted"])
def test_a_payload_swapping_the_endpoints_fields_never_crashes_and_both_cores_agree(
        plan: list[tuple[str, str, str]], direction: str) -> None:
    found = _in_a_child("dataclass field property", direction, plan)
    assert found["python fired"] == ["dataclass field property"]
    assert found["python"] == found["compiled"]
    if direction == "send" and any(where == "channels" for where, _, _ in plan):
        # the outbox itself was changed under the send: both unpack its entry as Python does
        assert found["python"][0][:2] == ["ValueError", "too many values to unpack (expected 2)"]
    else:  # the call under attack used what it read first
        assert found["python"][0][0] == "returned"


# ---- item 13: lies about a payload's class ----------------------------------------------------------

_CORES = [pytest.param("compiled", marks=needs_compiled), "python"]
_LIARS = {
    "metaclass __eq__ says int": ("num", ClaimsInt, "expected a payload of sort int, got ClaimsInt"),
    "metaclass __name__ says int": ("num", Nameless, "expected a payload of sort int, got Nameless"),
    "__class__ says int": ("num", PosesAsInt, "expected a payload of sort int, got PosesAsInt"),
    "int subclass __ge__ says >= 0": ("n", lambda: NegativeInt(-5), "expected a payload of sort nat (>= 0), got -5"),
    "a field's metaclass says int": ("record", lambda: Record(ClaimsInt()),  # type: ignore[arg-type]
                                     "field x of Record: expected int, got ClaimsInt"),
}


@pytest.mark.parametrize("direction", ["send", "recv"])
@pytest.mark.parametrize("core", _CORES)
@pytest.mark.parametrize("liar", list(_LIARS))
def test_a_payload_lying_about_its_class_passes_neither_monitor(liar: str, core: str, direction: str) -> None:
    label, make, reason = _LIARS[liar]
    outcomes = _one_message(core, direction, label, make())
    assert outcomes[0] == "ProtocolViolationError", outcomes
    assert reason in outcomes[1]
    assert ("violation by A" in outcomes[1]) and (f"role {'A' if direction == 'send' else 'B'}" in outcomes[1])


def _one_message(core: str, direction: str, label: str, payload: object) -> list[str]:
    """The outcome of sending (or receiving) one message on ``core``, no mutation planned."""
    hostile_payloads.PLAN.clear()
    cls = Endpoint if core == "compiled" else PythonEndpoint
    import sessiontypes
    from anodize._transport.inproc import InprocNetwork
    protocol = sessiontypes.loads(hostile_payloads.PROTOCOL, "hostile.proto").globals["G"]
    network = InprocNetwork([("A", "B"), ("B", "A")])
    if direction == "send":
        sender = cls("A", "G", protocol.project("A").fsm(), network)
        return hostile_payloads._outcome(sender.send, "B", label, payload)
    receiver = cls("B", "G", protocol.project("B").fsm(), network)
    network.queues[("A", "B")].put((label, payload))
    return hostile_payloads._outcome(receiver.recv, "A")


class RealInt(int):
    """A real subclass of int: the full check lets it pass (the subclass policy)."""


@pytest.mark.parametrize("direction", ["send", "recv"])
@pytest.mark.parametrize("core", _CORES)
def test_real_subclasses_pass_the_full_check_and_bool_is_not_an_int(core: str, direction: str) -> None:
    assert _one_message(core, direction, "num", RealInt(3))[0] == "returned"
    assert _one_message(core, direction, "n", RealInt(3))[0] == "returned"
    assert _one_message(core, direction, "num", True)[0] == "ProtocolViolationError"
    assert _one_message(core, direction, "record", Record(RealInt(1)))[0] == "returned"


def test_the_monitor_looks_payload_types_up_by_identity_never_by_hash() -> None:
    """The step's exact types are identities (and the types themselves, which keep them so)."""
    import sessiontypes
    protocol = sessiontypes.loads(hostile_payloads.PROTOCOL, "hostile.proto").globals["G"]
    machine = protocol.project("A").fsm()
    step = Monitor(machine, "G", "A").sends[machine.initial][("B", "num")]
    assert step[1] is int and step[4] == (int,) and step[5] == frozenset({id(int)})
    hostile_payloads.FIRED.clear()
    monitor = Monitor(machine, "G", "A")
    with pytest.raises(Exception, match="got ClaimsInt"):
        monitor.send("B", "num", ClaimsInt())
    assert hostile_payloads.FIRED == []  # neither the metaclass's __hash__ nor its __eq__ ran


# ---- generated mutations, each example in a forked child ------------------------------------------

_ATTRIBUTES = {
    "endpoint": ("role", "_plain", "_monitor", "_network", "_out", "_in", "sent", "received", "_waiting",
                 "high_water", "_doorbell", "_lending", "_stop_event", "_machine", "protocol"),
    "monitor": tuple(Monitor.__slots__),
    "channels": ("A", "B"),
}
_steps = st.sampled_from(sorted(_ATTRIBUTES)).flatmap(
    lambda where: st.tuples(st.just(where), st.sampled_from(_ATTRIBUTES[where]),
                            st.sampled_from(sorted(hostile_payloads.REPLACEMENTS))))


def _forked(hook: str, direction: str, plan: list[tuple[str, str, str]]) -> dict[str, Any]:
    """both_cores() in a forked child (bounded: 30 s), so that a crash is seen, not suffered."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        code = 0
        try:
            os.close(read)
            signal.alarm(30)
            os.write(write, json.dumps(both_cores(hook, direction, plan)).encode())
        except BaseException:  # the parent sees the exit code
            code = 3
        finally:
            os._exit(code)
    os.close(write)
    data = b""
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([read], [], [], 1.0)
            if ready:
                chunk = os.read(read, 65536)
                if not chunk:
                    break
                data += chunk
        else:
            os.kill(pid, signal.SIGKILL)
    finally:
        os.close(read)
        _, status = os.waitpid(pid, 0)
    assert not os.WIFSIGNALED(status), f"the child was killed by signal {os.WTERMSIG(status)} for {plan}"
    assert os.WEXITSTATUS(status) == 0, f"the child failed ({os.WEXITSTATUS(status)}) for {plan}"
    found: dict[str, Any] = json.loads(data)
    return found


@needs_compiled
@settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(HOOKS), st.sampled_from(["send", "recv"]), st.lists(_steps, min_size=1, max_size=3))
def test_generated_mutations_by_a_payloads_code_never_crash_either_core(
        hook: str, direction: str, plan: list[tuple[str, str, str]]) -> None:
    found = _forked(hook, direction, plan)
    for core in ("python", "compiled"):
        for outcome in found[core]:
            assert outcome[0] not in ("SystemError", "MemoryError"), (core, outcome)
    if any(where == "monitor" for where, _, _ in plan):  # the monitor's own tables are the compiled core's cache
        return
    if any(field == "_monitor" for _, field, _ in plan):
        # Another object as the monitor: each core fails on the first of its methods that it lacks,
        # and the two look them up in different orders. The same kind of outcome is what must agree.
        assert [o[0] for o in found["python"]] == [o[0] for o in found["compiled"]], plan
    else:  # an object put in by the plan is named by its repr, whose address differs between the runs
        assert _without_addresses(found["python"]) == _without_addresses(found["compiled"]), plan


def _without_addresses(outcomes: Any) -> str:
    return re.sub(r" at 0x[0-9a-f]+", " at 0x…", json.dumps(outcomes))


def test_the_hostile_cases_run_here_too() -> None:
    """The helper's cases, in this process, on the Python core (which never crashed)."""
    outcomes = run_case("python", "__getattr__", "send", [("endpoint", "_out", "delete")])
    assert outcomes[0][0] == "returned"
    assert outcomes[1][0] == "AnodizeError" and "_out is missing" in outcomes[1][1]
