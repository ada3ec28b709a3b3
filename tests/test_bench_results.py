"""bench/runs.py's write_results: every result file says what it is and under what load it was taken."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]


def _runs() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_runs", REPO / "bench" / "runs.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


runs = _runs()


def test_a_result_file_carries_its_title_table_and_load(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    watch = runs.LoadWatch()
    path = tmp_path / "results" / "x.json"
    runs.write_results(path, {"table": [["measure", "value"], ["a", "1"]], "extra": 3}, 0.0, title="X",
                       how="one run", watch=watch)
    written = json.loads(path.read_text(encoding="utf-8"))
    assert (written["title"], written["how"], written["extra"]) == ("X", "one run", 3)
    assert written["load"]["cpus"] >= 1 and len(written["load"]["loadavg_start"]) == 3
    assert isinstance(written["load"]["busy"], bool) and "date" in written
    assert "load (1/5/15 min)" in capsys.readouterr().out


def test_a_result_without_a_table_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="expected the table as a list of rows"):
        runs.write_results(tmp_path / "x.json", {"table": "a | b"}, 0.0, title="X", how="h", watch=runs.LoadWatch())
    assert not (tmp_path / "x.json").exists()


def test_every_committed_result_was_written_so() -> None:
    for path in sorted((REPO / "bench" / "results").glob("*.json")):
        written = json.loads(path.read_text(encoding="utf-8"))
        assert {"title", "how", "table", "load"} <= set(written), path.name
