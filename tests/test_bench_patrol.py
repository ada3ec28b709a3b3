"""bench/patrol_runs.py (``bench/tinman.py --patrol``): what it reads of each run's report.json,
and its table of medians and ranges per load."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType
from typing import Any

REPO = Path(__file__).resolve().parents[1]


def _module() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_patrol_runs", REPO / "bench" / "patrol_runs.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


patrol = _module()


def _report(*, completed: bool, time_s: float | None, waypoints: int, **extra: Any) -> dict[str, Any]:
    return {"mission": {"patrol_completed": completed, "completed_in_s": time_s,
                        "ended_by": "patrol completed" if completed else "time limit",
                        "waypoints_reached": [{"number": n} for n in range(1, waypoints + 1)],
                        "bumps": 0, "safety_stops": 2, "recoveries": None},
            "vo_ate_percent": 1.5, "control_period_ms": {"p50": 20.0, "p99": 21.0}, "duration_s": 50.0, **extra}


def test_a_run_is_read_from_its_report() -> None:
    run = patrol.read_run(_report(completed=True, time_s=48.0, waypoints=5), 0)
    assert (run["completed"], run["time_s"], run["waypoints"], run["bumps"]) == (True, 48.0, 5, 0.0)
    assert run["recoveries"] is None and run["fused_ate_percent"] is None and run["control_p99_ms"] == 21.0
    report = _report(completed=True, time_s=48.0, waypoints=5, fused_ate_percent=0.7,
                     recovery={"recoveries": 2, "time_to_recover_s": {"p50": 0.3, "max": 0.5}})
    run = patrol.read_run(report, 0)
    assert (run["fused_ate_percent"], run["vo_ate_percent"], run["recover_max_s"]) == (0.7, 1.5, 0.5)
    assert patrol.read_run({}, 1)["completed"] is False  # no mission at all: nothing invented


def test_the_table_gives_medians_with_their_range_and_dashes_for_what_no_run_reported() -> None:
    runs = [patrol.read_run(_report(completed=True, time_s=t, waypoints=5), 0) for t in (50.0, 46.0)]
    runs.append(patrol.read_run(_report(completed=False, time_s=None, waypoints=3), 1))
    runs.append({"load": "quiet", "error": "no report"})
    rows = patrol.table({"quiet": patrol.summarise(runs)})
    header, row = rows
    cells = dict(zip(header, row, strict=True))
    assert cells["runs"] == "4 (1 no report)" and cells["patrol completed"] == "2 of 3"
    assert cells["time to complete, s"] == "48.0 (46.0 to 50.0)"  # of the completed runs only
    assert cells["waypoints reached"] == "5 (3 to 5)" and cells["bumps (runs with any)"] == "0 (0)"
    assert cells["recoveries"] == "-" and cells["fused ATE / path"] == "-" and cells["longest recovery, s"] == "-"
    assert cells["VO ATE / path"] == "1.50%" and cells["control period p99, ms"] == "21.0"
