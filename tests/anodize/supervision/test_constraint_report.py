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
