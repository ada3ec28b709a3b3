"""Endpoint.statistics(): one frozen record per endpoint, branches included; the old dict methods warn."""

from __future__ import annotations

import dataclasses

import pytest

import anodize
import sessiontypes
from anodize import Endpoint, EndpointStatistics

PING = sessiontypes.loads("""
global Ping(A, B) = mu t. A -> B : {ping(nat). B -> A : pong(nat). t, stop}
""", "ping.proto").globals["Ping"]

SPLIT = sessiontypes.loads("""
global Split(C, M, P) = ( mu c. C -> M : {go. c, done} || mu p. P -> M : {plan. p, done} )
""", "split.proto").globals["Split"]


def _run(global_type: sessiontypes.GlobalType, **roles: object) -> anodize.RunReport:
    system = anodize.System(global_type)
    group = system.group("all")
    for name, function in roles.items():
        group.role(name, function)  # type: ignore[arg-type]
    return system.run(timeout=10)


def test_statistics_count_what_the_endpoint_did_and_do_not_change_afterwards() -> None:
    seen: dict[str, EndpointStatistics] = {}

    def a(ep: Endpoint) -> None:
        for number in range(3):
            ep.send("B", "ping", number)
            ep.recv("B")
        before = ep.statistics()
        ep.send("B", "stop")
        seen["before"], seen["after"] = before, ep.statistics()

    def b(ep: Endpoint) -> None:
        while (message := ep.recv("A")).label == "ping":
            ep.send("A", "pong", message.payload)

    assert _run(PING, A=a, B=b).ok
    before, after = seen["before"], seen["after"]
    assert (dict(before.sent), dict(before.received)) == ({"B": 3}, {"B": 3})
    assert (dict(after.sent), dict(after.received)) == ({"B": 4}, {"B": 3})
    assert set(after.high_water) <= {"B"} and all(n >= 0 for n in after.high_water.values())
    with pytest.raises(dataclasses.FrozenInstanceError):
        after.sent = {}  # type: ignore[misc]
    with pytest.raises(TypeError):
        after.sent["B"] = 0  # type: ignore[index]


def test_statistics_add_up_the_parallel_branches() -> None:
    seen: dict[str, EndpointStatistics] = {}

    def c(ep: Endpoint) -> None:
        ep.send("M", "go")
        ep.send("M", "go")
        ep.send("M", "done")

    def p(ep: Endpoint) -> None:
        ep.send("M", "plan")
        ep.send("M", "done")

    def m(ep: Endpoint) -> None:
        control, planning = ep.fork()
        while control.recv("C").label == "go":
            pass
        while planning.recv("P").label == "plan":
            pass
        seen["M"] = ep.statistics()

    assert _run(SPLIT, C=c, M=m, P=p).ok
    assert dict(seen["M"].received) == {"C": 3, "P": 2}
    assert dict(seen["M"].sent) == {}


def test_the_old_dict_methods_warn_and_agree_with_statistics() -> None:
    seen: dict[str, object] = {}

    def a(ep: Endpoint) -> None:
        ep.send("B", "stop")
        statistics = ep.statistics()
        with pytest.warns(DeprecationWarning, match=r"statistics\(\)\.sent"):
            seen["sent"] = (ep.sent_counts(), dict(statistics.sent))
        with pytest.warns(DeprecationWarning, match=r"statistics\(\)\.received"):
            seen["received"] = (ep.received_counts(), dict(statistics.received))
        with pytest.warns(DeprecationWarning, match=r"statistics\(\)\.high_water"):
            seen["high_water"] = (ep.high_water_marks(), dict(statistics.high_water))

    def b(ep: Endpoint) -> None:
        ep.recv("A")

    assert _run(PING, A=a, B=b).ok
    assert seen["sent"] == ({"B": 1}, {"B": 1})
    for old, new in seen.values():  # type: ignore[misc]
        assert old == new
