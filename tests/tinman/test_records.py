"""TinMan's records are written by roles, so the report reads them as untrusted input."""

from __future__ import annotations

from pathlib import Path

from tinman.records import load_records


def test_records_that_are_not_json_objects_are_skipped(tmp_path: Path) -> None:
    (tmp_path / "Good.json").write_text('{"frames": 3}', encoding="utf-8")
    (tmp_path / "List.json").write_text("[1, 2]", encoding="utf-8")            # .get() on it was AttributeError
    (tmp_path / "Deep.json").write_text("[" * 100_000 + "]" * 100_000, encoding="utf-8")  # was RecursionError
    (tmp_path / "Bytes.json").write_bytes(b'{"a": "\xff"}')
    (tmp_path / "Folder.json").mkdir()
    assert load_records(tmp_path) == {"Good": {"frames": 3}}
