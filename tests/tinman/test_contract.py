"""TinMan's contract section: the roles' constraint statistics, per interaction and side, in the report."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from anodize import ProtocolViolationError
from anodize.errors import Action
from tinman.contract import contract_lines, contract_report

RECORDS: dict[str, dict[str, Any]] = {
    "Joy": {"contract": {"!Control(Joy) every 20ms +- 15ms": {"checked": 1503, "closest_ms": 8.6}}},
    "Camera": {"contract": {"?Gazebo(color(Image)) within 1s else timeout": {"checked": 40, "closest_ms": 12.0}}},
    "Move": {"contract": {"?VisOdom(Pose) within 500ms else timeout": {"checked": 90, "closest_ms": -0.1}},
             "estimate_timeouts": 3},
    "Planner": {"plans": 4},  # no constraint: no entry
}


def test_each_constrained_interaction_and_side_is_an_entry_with_its_counts_and_margin() -> None:
    contract = contract_report(RECORDS, SimpleNamespace(roles={}))  # type: ignore[arg-type]
    assert [(e["interaction"], e["constraints"], e["side"], e["checked_by"]) for e in contract] == [
        ("Gazebo -> Camera: color(Image)", "within 1s else timeout", "receives", "Camera"),
        ("Joy -> Control: Joy", "every 20ms +- 15ms", "sends", "Joy"),
        ("VisOdom -> Move: Pose", "within 500ms else timeout", "receives", "Move")]
    assert all(entry["held"] for entry in contract)
    assert contract[2]["timeouts"] == 3 and contract[0]["timeouts"] is None
    assert contract_lines(contract)[1] == ("contract: Joy -> Control: Joy every 20ms +- 15ms: 1,503 sends checked "
                                           "by Joy, closest margin 8.6 ms, held")
    assert contract_lines(contract)[2].endswith("closest margin -0.1 ms, 3 timeouts taken, held")


def violation(reason: str) -> ProtocolViolationError:
    return ProtocolViolationError("TinManParallel", "Joy", "Control", "0", [], Action("send", "Control", "Joy"),
                                  blame="Joy", reason=reason)


def test_a_refused_send_is_a_violation_of_the_sender_s_entry_with_its_blame() -> None:
    records = {"Joy": RECORDS["Joy"], "Control": {"contract": {"?Joy(Joy) every 20ms +- 15ms": {"checked": 7}}}}
    other = SimpleNamespace(roles={"Joy": SimpleNamespace(error=violation("a wrong label"))})
    assert all(entry["held"] for entry in contract_report(records, other))  # type: ignore[arg-type]
    error = violation("refinement {x > 0} is false for Joy")
    control, joy = contract_report(records, SimpleNamespace(roles={"Joy": SimpleNamespace(error=error)}))  # type: ignore[arg-type]
    assert (joy["held"], control["held"]) == (False, True)  # raised on the sender's side: its entry
    [found] = joy["violations"]
    assert (found["blame"], found["raised_at"], found["interaction"]) == ("Joy", "Joy", "Joy -> Control")
    assert contract_lines([joy])[0].endswith("VIOLATED: blamed on Joy: " + str(error))
