"""Records are kept by a launched run only: a role run on its own (as ``anodize replay`` runs it)
writes none, so it cannot overwrite the records of the run it replays; and roles write them, so
the report reads them as untrusted input."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from tinman.records import load_records, records_folder, save_record
from tinman.settings import ENVIRONMENT_VARIABLE, Settings, current, export


@pytest.fixture(autouse=True)
def fresh_settings(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    monkeypatch.delenv(ENVIRONMENT_VARIABLE, raising=False)  # restored after the test, with what export sets
    current.cache_clear()
    yield
    current.cache_clear()


def test_a_role_run_on_its_own_writes_no_record(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.chdir(tmp_path)  # where the default settings' folder, out/tinman/records, is a recorded run's
    recorded = Path(Settings().records)
    recorded.mkdir(parents=True)
    (recorded / "Planner.json").write_text(json.dumps({"plans": 40}))
    assert records_folder() is None
    assert save_record("Planner", {"plans": 2}) is None
    assert load_records(recorded) == {"Planner": {"plans": 40}}
    assert sorted(p.name for p in recorded.iterdir()) == ["Planner.json"]


def test_a_launched_run_keeps_its_records(tmp_path: Path) -> None:
    export(Settings(out=str(tmp_path / "run")))
    assert records_folder() == tmp_path / "run" / "records"
    assert save_record("Planner", {"plans": 2}) == tmp_path / "run" / "records" / "Planner.json"
    assert load_records(tmp_path / "run" / "records") == {"Planner": {"plans": 2}}


def test_records_that_are_not_json_objects_are_skipped(tmp_path: Path) -> None:
    (tmp_path / "Good.json").write_text('{"frames": 3}', encoding="utf-8")
    (tmp_path / "List.json").write_text("[1, 2]", encoding="utf-8")            # .get() on it was AttributeError
    (tmp_path / "Deep.json").write_text("[" * 100_000 + "]" * 100_000, encoding="utf-8")  # was RecursionError
    (tmp_path / "Bytes.json").write_bytes(b'{"a": "\xff"}')
    (tmp_path / "Folder.json").mkdir()
    assert load_records(tmp_path) == {"Good": {"frames": 3}}
