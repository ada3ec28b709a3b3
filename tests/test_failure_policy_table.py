"""The failure-policy table in docs/guide/failure-policies.md: a row for every policy the system
file allows (and for a restart used up) and every place a failure can be; every cell names a test
that exists, or says why it names none ("—" for a place the transport cannot be, "to do")."""

from __future__ import annotations

import re
from pathlib import Path

from anodize._supervision.group import FailurePolicy

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs/guide/failure-policies.md"
WHERE = ("same host", "another host", "another host, cut off and back")
TRANSPORTS = ("inproc", "process", "dds", "zenoh")
REFERENCE = re.compile(r"`(tests/[\w/]+\.py)::(test_\w+)(?:\[([\w-]+)\])?`")


def table() -> list[list[str]]:
    rows = [[cell.strip() for cell in line.strip().strip("|").split("|")]
            for line in PAGE.read_text().splitlines() if line.startswith("|")]
    assert rows[0] == ["policy", "where the failure is", *TRANSPORTS], rows[0]
    return rows[2:]  # past the header and its rule


def test_every_policy_and_place_has_a_row() -> None:
    policies = [p.value for p in FailurePolicy] + ["restart, used up"]
    rows = [(row[0], row[1]) for row in table()]
    assert sorted(rows) == sorted((p, w) for p in policies for w in WHERE), rows


def test_every_cell_names_a_test_or_says_why_not() -> None:
    for row in table():
        for transport, cell in zip(TRANSPORTS, row[2:], strict=True):
            assert REFERENCE.search(cell) or cell.startswith(("—", "to do")), (row[:2], transport, cell)


def test_every_test_the_page_names_exists() -> None:
    named = REFERENCE.findall(PAGE.read_text())
    assert len(named) > 20
    for file, test, case in named:
        source = (REPO / file).read_text()
        assert re.search(rf"^def {test}\(", source, re.M), f"{file}::{test} does not exist"
        if case:  # a parametrized case: its id is in the file (pytest.param(..., id=...), or a param list)
            assert f'"{case}"' in source, f"{file}::{test}[{case}]: no case {case!r} there"
