"""The run report says how each constrained interaction fared: its checks and the closest it
came to its time bound, gathered from every group (in-process and process runners alike)."""

from __future__ import annotations

import pytest
import timed_roles

import anodize
import sessiontypes

# The controller of timed_roles, with a deadline on both parties and a bound on the value.
TIMED = "global G(C, M) = mu t. C -> M : { cmd(v: int{0 <= v <= 10}). t, stop. end } within 5s"


def _run(transport: anodize.Transport) -> anodize.RunReport:
    gt = sessiontypes.loads(TIMED, "timed.proto").globals["G"]
    system = anodize.System(gt, transport=transport)
    system.group("control").role("C", timed_roles.punctual)
    system.group("motor").role("M", timed_roles.motor)
    return system.run(timeout=30.0)


@pytest.mark.parametrize("transport", [anodize.Inproc(), anodize.Processes()], ids=["inproc", "process"])
def test_the_report_counts_each_constrained_interaction_and_its_closest_margin(transport: anodize.Transport) -> None:
    report = _run(transport)
    assert report.ok, report.summary()
    # punctual sends three cmd and a stop: each checked once at C (sender) and once at M (receiver).
    for role in ("C", "M"):
        mine = {key: c for key, c in report.constraints.items() if key.startswith(f"{role} ")}
        assert sum(int(c["checked"] or 0) for c in mine.values()) == 4, report.constraints
        margins = [c["closest_s"] for c in mine.values()]
        assert all(m is not None and 0 < m <= 5.0 for m in margins), margins
    cmd = next(key for key in report.constraints if key.startswith("C ") and "cmd" in key)
    assert "within 5s" in cmd and cmd.count("{0 <= v <= 10}") == 1
    assert f"  constraint {cmd}: 3 checked, closest " in report.summary()
    assert report.to_dict()["constraints"] == report.constraints


def test_an_unconstrained_run_reports_no_constraints() -> None:
    gt = sessiontypes.loads(timed_roles.CONTROL, "plain.proto").globals["G"]
    system = anodize.System(gt, transport=anodize.Inproc())
    system.group("control").role("C", timed_roles.punctual)
    system.group("motor").role("M", timed_roles.motor)
    report = system.run(timeout=30.0)
    assert report.ok and report.constraints == {} and "constraint" not in report.summary()


def test_timeouts_taken_are_counted_apart_from_misses() -> None:
    """A deadline with ``else timeout`` that passes is the protocol's way on: counted as a
    timeout taken, not as a margin missed."""
    gt = sessiontypes.loads("global W(S, M) = mu t. S -> M : { r(c: float). t, stop } within 50ms else timeout",
                            "w.proto").globals["W"]

    def sensor(ep: anodize.Endpoint) -> None:
        ep.send("M", "r", {"c": 1.0})
        ep.sleep(0.6)  # at least five of the monitor's 50 ms pass with nothing, however late it wakes
        ep.send("M", "stop")

    def monitor(ep: anodize.Endpoint) -> None:
        while ep.recv("S").label != "stop":
            pass

    system = anodize.System(gt, transport=anodize.Inproc())
    system.group("s").role("S", sensor)
    system.group("m").role("M", monitor)
    report = system.run(timeout=30.0)
    assert report.ok, report.summary()
    taken = sum(int(c["timeouts"] or 0) for key, c in report.constraints.items() if key.startswith("M "))
    assert taken >= 5, report.constraints
    assert all((c["closest_s"] or 0) >= 0 for c in report.constraints.values()), report.constraints
    assert f", {taken} timeouts taken" in report.summary()
