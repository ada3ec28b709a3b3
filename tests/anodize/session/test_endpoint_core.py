"""The compiled core of ``Endpoint`` (``_endpoint_core.c``) against the Python core.

The compiled ``send`` and ``recv`` take the commonest path in C and hand the rest to the
Python ones, which stay the reference. Here both cores are driven through the same random
actions (allowed and not: any peer, any label, payloads of any type, signals in the
channels) on generated protocols, and must agree at every step: what returns or what is
raised (type and message), the monitor's state, the counts, and what each channel holds.
``test_the_endpoint_tests_pass_on_the_python_core`` then runs the endpoint test files in a
process where ``ANODIZE_PURE_PYTHON=1`` leaves the compiled core out altogether.
"""

from __future__ import annotations

import os
import queue
import random
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from budget import examples
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

_HERE = Path(__file__).resolve().parents[1]
for _folder in (_HERE, _HERE.parent / "sessiontypes"):
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))

from role_drivers import load_global, machines_of, payload_for  # noqa: E402
from strategies import GeneratedGlobal, global_protocols  # noqa: E402

from anodize import RoleStopped  # noqa: E402
from anodize._session.channel import STOP, Corrupt, PeerFailure  # noqa: E402
from anodize._session.endpoint import COMPILED_CORE, Endpoint  # noqa: E402
from anodize._transport.codec import Codec  # noqa: E402
from anodize._transport.inproc import InprocNetwork  # noqa: E402
from anodize._transport.network import GroupNetwork  # noqa: E402
from anodize._transport.process import PipeLinks  # noqa: E402

needs_compiled = pytest.mark.skipif(COMPILED_CORE is None, reason="anodize was installed without a C compiler "
                                    "or Python's headers, so the compiled core was not built")


class PythonEndpoint(Endpoint):
    """An endpoint on the Python core, whatever its base class."""

    send = Endpoint._send_python
    recv = Endpoint._recv_python


def _outcome(call: Any, *args: object) -> tuple[str, str]:
    try:
        return "returned", repr(call(*args))
    except (Exception, RoleStopped) as error:  # compared, not handled
        return type(error).__name__, str(error)


def _contents(channel: Any) -> list[object]:
    """What a channel holds, taken out and put back."""
    items = []
    while True:
        try:
            items.append(channel.get_nowait())
        except queue.Empty:
            break
    for item in items:
        channel.put(item)
    return [item if isinstance(item, tuple)
            else f"Corrupt({item.reason})" if isinstance(item, Corrupt) else repr(item) for item in items]


def _signal(kind: int, peer: str) -> object:
    return [PeerFailure(peer, "crashed"), STOP, Corrupt("bad frame")][kind]


def _setup(cls: type[Endpoint], generated: GeneratedGlobal, role: str,
           monitored: bool) -> tuple[Endpoint, InprocNetwork]:
    global_type = load_global(generated.text)
    machines = machines_of(global_type)
    network = InprocNetwork([(a, b) for a in global_type.roles for b in global_type.roles if a != b],
                            doorbell_roles=[r for r, machine in machines.items() if machine.forks])
    return cls(role, "G", machines[role], network, monitored), network


def _protocol(text: str) -> GeneratedGlobal:
    roles = tuple(text[text.index("(") + 1:text.index(")")].split(", "))
    return GeneratedGlobal(text, None, roles)  # type: ignore[arg-type]


@needs_compiled
@settings(max_examples=examples(150), deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(global_protocols(), st.data(), st.booleans())
def test_both_cores_agree_on_every_action(generated: GeneratedGlobal, data: st.DataObject, monitored: bool) -> None:
    roles = generated.roles
    role = data.draw(st.sampled_from(roles))
    compiled, compiled_net = _setup(Endpoint, generated, role, monitored)
    python, python_net = _setup(PythonEndpoint, generated, role, monitored)
    assert type(compiled).send is not type(python).send
    machine = machines_of(load_global(generated.text))[role]
    labels = sorted({t.label for t in machine.all_transitions() if t.label} | {"bogus"})
    sorts = [t.sort for t in machine.all_transitions()]
    rng = random.Random(data.draw(st.integers(0, 2**32 - 1)))
    peers = [r for r in roles if r != role] + ["Nobody"]
    for _ in range(data.draw(st.integers(1, 30))):
        peer = data.draw(st.sampled_from(peers))
        payload = rng.choice([None, 1, True, "x", 2.5, b"b", [1], {"x": 1}, payload_for(rng.choice(sorts), rng)])
        label = data.draw(st.sampled_from(labels))
        action = data.draw(st.sampled_from(["send", "send", "recv", "recv", "incoming", "signal", "alarm",
                                            "allowed", "allowed", "allowed"]))
        if action == "allowed":  # what the local type allows now, with a payload of its sort
            state = python._monitor.state if python._monitor is not None else None
            allowed = machine.expected(state) if isinstance(state, int) else []
            if not allowed:
                continue
            step = rng.choice(allowed)
            assert step.peer is not None
            peer, label, payload = step.peer, step.label, payload_for(step.sort, rng)
            if step.action == "recv":  # it arrives first
                for net in (compiled_net, python_net):
                    net.queues[(peer, role)].put((label, payload))
            action = step.action
        if action == "incoming" and peer != "Nobody":  # a message arrives from peer, allowed or not
            for net in (compiled_net, python_net):
                net.queues[(peer, role)].put((label, payload))
            continue
        if action == "signal" and peer != "Nobody":
            kind = rng.randrange(3)
            for net in (compiled_net, python_net):
                net.queues[(peer, role)].put(_signal(kind, peer))
            continue
        if action == "alarm":  # a peer failed, which every later send to it must refuse
            for net in (compiled_net, python_net):
                net.failed[peer] = "crashed"
                net.alarm = True
            continue
        results = []
        for endpoint, net in ((compiled, compiled_net), (python, python_net)):
            if action == "send":
                results.append(_outcome(endpoint.send, peer, label, payload))
            else:
                channel = net.queues.get((peer, role))
                # recv() without a timeout must never block here: only on a channel holding something.
                timeout = None if channel is not None and not channel.empty() else 0
                args = (peer,) if timeout is None and rng.random() < 0.5 else (peer, timeout)
                results.append(_outcome(endpoint.recv, *args))
        assert results[0] == results[1], (action, peer, label, payload)
        assert compiled.state == python.state
        assert (compiled.sent, compiled.received, compiled.high_water) == (python.sent, python.received,
                                                                           python.high_water)
        for pair in compiled_net.queues:
            assert _contents(compiled_net.queues[pair]) == _contents(python_net.queues[pair]), pair
        for ringing in compiled_net.doorbells:  # roles with parallel branches: a ring per message
            assert _contents(compiled_net.doorbells[ringing]) == _contents(python_net.doorbells[ringing])


@settings(max_examples=examples(150), deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(global_protocols(), st.data())
def test_a_batch_does_what_its_messages_one_by_one_do(generated: GeneratedGlobal, data: st.DataObject) -> None:
    """``send_many`` against ``send`` in a loop, and ``recv_many`` against ``recv`` in a loop: the
    same messages go or come, the same state follows, the same error ends the batch."""
    roles = generated.roles
    role = data.draw(st.sampled_from(roles))
    machine = machines_of(load_global(generated.text))[role]
    steps = [t for t in machine.expected(machine.initial) if t.peer is not None]  # where the batch starts
    if not steps:
        return
    rng = random.Random(data.draw(st.integers(0, 2**32 - 1)))
    chosen = data.draw(st.sampled_from(steps))
    values = [payload_for(chosen.sort, rng) for _ in range(data.draw(st.integers(0, 12)))]
    values += data.draw(st.lists(st.sampled_from([None, 1, "x", 2.5, True, b"b"]), max_size=3))
    values = data.draw(st.permutations(values))
    _compare_batch(generated, role, chosen.action, chosen.peer, chosen.label, values)


def _compare_batch(generated: GeneratedGlobal, role: str, action: str, peer: str, label: str,
                   values: list[object]) -> None:
    """``send_many``/``recv_many`` of ``values`` against ``send``/``recv`` one by one."""
    batch, batch_net = _setup(Endpoint, generated, role, True)
    single, single_net = _setup(Endpoint, generated, role, True)
    if action == "send":
        expected = ("returned", repr(len(values)))
        for value in values:
            result = _outcome(single.send, peer, label, value)
            if result[0] != "returned":
                expected = result
                break
        assert _outcome(batch.send_many, peer, label, values) == expected
    elif values:
        if action == "recv pipe":  # between processes, where recv_many takes what one read brought
            batch, batch_net = _pipe_setup(generated, role, peer)
            single, single_net = _pipe_setup(generated, role, peer)
        for net in (batch_net, single_net):
            for value in values:
                net.queues[(peer, role)].put((label, value))
        got: list[Any] = []
        outcome = _outcome(lambda: got.extend(batch.recv_many(peer, 1024, 0)))
        if outcome[0] != "returned":  # the first is received as recv() would receive it: so it fails
            assert _outcome(single.recv, peer, 0) == outcome
        # Then as many as recv() takes one by one, stopping before any it would have to refuse.
        assert got == [single.recv(peer, 0) for _ in got]
    assert (batch.state, batch.sent, batch.received) == (single.state, single.sent, single.received)
    if action == "recv pipe":
        rest = len(values) - batch.received[peer]  # what recv_many left is there, for recv to take
        assert [_outcome(batch.recv, peer, 0) for _ in range(rest)] == [_outcome(single.recv, peer, 0)
                                                                         for _ in range(rest)]
        return
    for pair in batch_net.queues:
        assert _contents(batch_net.queues[pair]) == _contents(single_net.queues[pair]), pair


def _pipe_setup(generated: GeneratedGlobal, role: str, peer: str) -> tuple[Endpoint, Any]:
    """An endpoint of ``role`` whose channel from ``peer`` is a pipe; the network's queue for that
    pair is the pipe's sending end, so a test puts messages there as ``peer`` would."""
    global_type = load_global(generated.text)
    read, write = os.pipe()
    channels = [(a, b) for a in global_type.roles for b in global_type.roles if a != b]
    receiving = GroupNetwork([role], channels, PipeLinks({(peer, role): read}), {}, lambda pair: Codec())
    sending = GroupNetwork([peer], channels, PipeLinks({(peer, role): write}), {}, lambda pair: Codec())
    endpoint = Endpoint(role, "G", machines_of(global_type)[role], receiving, True)
    sending.queues = {(peer, role): sending.queues[(peer, role)]}
    return endpoint, sending


STREAMS = _protocol("global G(A, B) = mu t. A -> B : { l0(int). t, l1(str). B -> A : l2. end, "
                    "l3(int). A -> B : l3(int). A -> B : l3(int). end }")


@pytest.mark.parametrize(("role", "action", "peer", "label", "values"), [
    ("A", "send", "B", "l0", [1, 2, 3, 4]),
    ("A", "send", "B", "l0", [1, 2, "x", 4]),  # a payload of another type stops the batch there
    ("A", "send", "B", "l0", [1, True, 3]),  # a bool is not an int here
    ("A", "send", "B", "l1", ["x", "y"]),  # leaves the loop: the second is refused
    ("B", "recv", "A", "l0", [1, 2, 3, 4]),
    ("B", "recv", "A", "l0", [1, 2, 2.5, 4]),
    ("B", "recv", "A", "l1", ["x", "y"]),
    ("B", "recv pipe", "A", "l0", [1, 2, 3, 4]),
    ("B", "recv pipe", "A", "l0", [1, 2, 2.5, 4]),
    ("B", "recv pipe", "A", "l0", [1, 2, None, 4]),
    ("B", "recv pipe", "A", "l1", ["x", "y"]),
    ("B", "recv pipe", "A", "l3", [1, 2, 3, 4]),  # the same label, but not a loop
    ("A", "send", "B", "l3", [1, 2, 3, 4]),
], ids=["loop", "loop, wrong type", "loop, bool", "leaves the loop", "recv loop", "recv loop, wrong type",
        "recv leaves the loop", "pipe loop", "pipe loop, wrong type", "pipe loop, None",
        "pipe leaves the loop", "pipe, same label, no loop", "same label, no loop"])
def test_a_batch_on_a_loop_checks_every_message(role: str, action: str, peer: str, label: str,
                                                values: list[object]) -> None:
    _compare_batch(STREAMS, role, action, peer, label, values)


@needs_compiled
def test_the_compiled_core_takes_keywords_and_defaults_as_the_python_core_does() -> None:
    generated = _protocol("global G(A, B) = mu t. A -> B : { num(int). t, fin }")
    compiled, network = _setup(Endpoint, generated, "A", True)
    compiled.send(to="B", label="num", payload=1)
    compiled.send("B", label="num", payload=2)
    compiled.send("B", "fin")
    assert _contents(network.queues[("A", "B")]) == [("num", 1), ("num", 2), ("fin", None)]
    receiver, network = _setup(Endpoint, generated, "B", True)
    network.queues[("A", "B")].put(("num", 3))
    network.queues[("A", "B")].put(("num", 4))
    assert receiver.recv(frm="A") == ("num", 3) and type(receiver.recv("A", timeout=1.0)).__name__ == "Message"
    with pytest.raises(TypeError):
        compiled.send()  # type: ignore[call-arg]


REPEATS = _protocol("global G(A, B, C) = A -> B : l0(int). A -> B : l0(int). B -> A : l1. B -> A : l1. "
                    "A -> B : l1(int). A -> C : l1(int). end")
LOOP = _protocol("global G(A, B) = mu t. A -> B : { l0(int). t, l1(int). B -> A : l0. B -> A : l1. end }")


@needs_compiled
@pytest.mark.parametrize(("protocol", "script"), [
    (REPEATS, [("send", "B", "l0", 1), ("send", "B", "l0", 2), ("send", "B", "l0", 3)]),  # the third is refused
    (REPEATS, [("send", "B", "l0", 1), ("send", "B", "l0", 2), ("recv", "B", "l1", None), ("recv", "B", "l1", None),
               ("recv", "B", "l1", None), ("send", "B", "l1", 4), ("send", "B", "l1", 5), ("send", "C", "l1", 6)]),
    (REPEATS, [("send", "B", "l0", 1), ("send", "B", "l0", 2.5), ("send", "B", "l0", 2)]),  # a refused payload
    (LOOP, [("send", "B", "l0", 1), ("send", "B", "l0", 2), ("send", "B", "l1", 3), ("recv", "B", "l0", None),
            ("recv", "B", "l0", None), ("recv", "B", "l1", None)]),  # the same state, another label
], ids=["same message, next state", "receives, then the same label to another peer", "payload type",
        "same state, other label"])
def test_a_repeated_message_is_checked_in_the_state_it_is_sent_in(
        protocol: GeneratedGlobal, script: list[tuple[str, str, str, object]]) -> None:
    """The compiled core remembers the last step it took each way; a message like the last one,
    in another state, with another label or to another peer, must still be checked there."""
    outcomes = []
    for cls in (Endpoint, PythonEndpoint):
        endpoint, network = _setup(cls, protocol, "A", True)
        seen = []
        for action, peer, label, payload in script:
            if action == "recv":
                network.queues[(peer, "A")].put((label, payload))
                seen.append((_outcome(endpoint.recv, peer), endpoint.state))
            else:
                seen.append((_outcome(endpoint.send, peer, label, payload), endpoint.state))
        outcomes.append(seen)
    assert outcomes[0] == outcomes[1]
    assert any(result[0] == "ProtocolViolationError" for result, _ in outcomes[0])


@pytest.mark.slow
def test_the_endpoint_tests_pass_on_the_python_core(tmp_path: Path) -> None:
    """The pure-Python fallback is what runs where nothing was compiled: it must pass the same tests."""
    # Not test_timed_monitor.py: a constrained step never takes the compiled path (it has no exact
    # types), so both cores run the monitor's same Python check; that file runs its own both-cores tests.
    files = ["session/test_endpoint_core.py", "session/test_runtime_properties.py", "session/test_send_many.py",
             "transport/test_frames.py", "transport/test_pipe_frames.py", "supervision/test_faults.py"]
    env = {**os.environ, "ANODIZE_PURE_PYTHON": "1"}
    check = ("from anodize._session.endpoint import COMPILED_CORE; from anodize._transport.frames import COMPILED; "
             "assert COMPILED_CORE is None and not COMPILED")
    subprocess.run([sys.executable, "-c", check], env=env, check=True)
    # Not the slow ones: they are about whole runs (a killed group, a GIL held for good), which
    # the core does not change, and the suite runs them once already.
    # A quarter of the property tests' examples: the compiled core met the full count in this suite.
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "-m", "not slow",
                             "--hypothesis-profile=rerun",
                             "-k", "not test_the_endpoint_tests_pass_on_the_python_core",
                             *(str(_HERE / name) for name in files)],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)  # nothing left here
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]


@needs_compiled
@pytest.mark.parametrize("replacement", ["another monitor", "not a monitor"])
def test_a_monitor_replaced_while_a_receive_waits_checks_as_the_python_core_does(replacement: str) -> None:
    """Any code can run in a channel's get(); should it replace the endpoint's monitor, the
    message is checked by the monitor read before, in both cores."""
    from anodize._session.monitor import Monitor

    def receive_after_a_replacement(cls: type[Endpoint]) -> tuple[tuple[str, str], object]:
        endpoint, network = _setup(cls, _protocol("global G(A, B) = mu t. A -> B : { num(int). t, fin }"), "B", True)
        channel = network.queues[("A", "B")]
        for number in range(2):
            channel.put(("num", number))
        endpoint.recv("A")  # the compiled core's tables and steps are cached now
        before = endpoint._monitor
        assert before is not None

        class Replacing:
            def put(self, item: object) -> None:
                channel.put(item)

            def get(self, timeout: float | None = None) -> object:
                endpoint._monitor = (Monitor(before.machine, "G", "B") if replacement == "another monitor"
                                     else object())  # type: ignore[assignment]
                return channel.get(timeout=timeout)

        endpoint._in["A"] = Replacing()  # type: ignore[assignment]
        return _outcome(endpoint.recv, "A"), before.state

    assert receive_after_a_replacement(PythonEndpoint) == receive_after_a_replacement(Endpoint)


@needs_compiled
def test_a_stand_in_monitor_with_the_monitors_descriptor_is_refused_as_python_refuses_it() -> None:
    from anodize._session.monitor import Monitor

    def send_with_a_stand_in(cls: type[Endpoint]) -> tuple[str, str]:
        endpoint, _ = _setup(cls, _protocol("global G(A, B) = mu t. A -> B : { num(int). t, fin }"), "A", True)
        real = endpoint._monitor
        assert real is not None

        class StandIn:  # not a Monitor: Monitor's slot descriptor does not apply to it
            state = Monitor.state
            sends, recvs, recv_peers = real.sends, real.recvs, real.recv_peers

            def send(self, *args: object) -> None:
                real.send(*args)  # type: ignore[arg-type]

        endpoint._monitor = StandIn()  # type: ignore[assignment]
        return _outcome(endpoint.send, "B", "num", 1)

    python, compiled = send_with_a_stand_in(PythonEndpoint), send_with_a_stand_in(Endpoint)
    assert python == compiled and python[0] == "TypeError"


@needs_compiled
def test_names_of_a_str_subclass_take_the_python_path_with_the_same_result() -> None:
    """A role name or label of a str subclass may run its own code inside a look-up: the compiled
    core leaves such calls to the Python core, and the outcome is the same."""
    class Name(str):
        def __eq__(self, other: object) -> bool:
            return str.__eq__(self, other)

        __hash__ = str.__hash__

    def run(cls: type[Endpoint]) -> list[tuple[str, str]]:
        stream = _protocol("global G(A, B) = mu t. A -> B : { num(int). t, fin }")
        sender, network = _setup(cls, stream, "A", True)
        results = [_outcome(sender.send, Name("B"), Name("num"), 1), _outcome(sender.send, "B", Name("num"), 2),
                   _outcome(sender.send, Name("B"), "nope", 3)]
        receiver, _ = _setup(cls, stream, "B", True)
        receiver._in["A"] = network.queues[("A", "B")]
        results += [_outcome(receiver.recv, Name("A")), _outcome(receiver.recv, "A")]
        return [*results, (sender.state, receiver.state)]

    assert run(PythonEndpoint) == run(Endpoint)


CYCLE = _protocol("global G(A, B) = mu t. A -> B : { x(int). A -> B : y(int). B -> A : z(int). t, stop }")


@needs_compiled
def test_a_loop_of_several_states_is_stepped_without_a_table_look_up_per_message() -> None:
    """Each state remembers the step it took last each way (and the peer it last let a receive
    wait for): a loop through three states looks its tables up once per state, not once per
    message. Counted by the core (``_lookups``), the same answers as the Python core."""
    rounds = 200
    sender, to_b = _setup(Endpoint, CYCLE, "A", True)
    receiver, _ = _setup(Endpoint, CYCLE, "B", True)
    receiver._in["A"] = to_b.queues[("A", "B")]
    sender._in["B"] = receiver._out["A"][0]
    for number in range(rounds):
        sender.send("B", "x", number)
        sender.send("B", "y", number)
        assert receiver.recv("A") == ("x", number) and receiver.recv("A") == ("y", number)
        receiver.send("A", "z", number)
        assert sender.recv("B") == ("z", number)
    # A: a send step in each of two states, a receive check and a step in the third; B alike.
    assert sender._lookups <= 4 and receiver._lookups <= 6, (sender._lookups, receiver._lookups)
    assert sender.state.startswith("0 (") and receiver.state.startswith("0 (")  # at the head of the loop again
    python_sender, _ = _setup(PythonEndpoint, CYCLE, "A", True)
    for number in range(3):
        python_sender.send("B", "x", number)
        python_sender.send("B", "y", number)
        python_sender._in["B"].put(("z", number))
        python_sender.recv("B")
    assert _outcome(python_sender.send, "B", "z", 1) == _outcome(sender.send, "B", "z", 1)
