"""What the benchmarks that run anodize systems share: settings handed to role functions in
group processes, and the results those roles write back."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["bench_env", "print_table", "write_results"]


@contextmanager
def bench_env(variable: str, **settings: Any) -> Iterator[tuple[str, Callable[[str], dict[str, Any]]]]:
    """``settings`` and a fresh output folder as JSON in the environment variable ``variable`` (group
    processes inherit it); yields the folder and a reader of ``<folder>/<name>.json``."""
    out = Path(tempfile.mkdtemp(prefix="anodize-bench-"))
    os.environ[variable] = json.dumps({"out": str(out), **settings})

    def result(name: str) -> dict[str, Any]:
        path = out / f"{name}.json"
        if not path.exists():
            raise RuntimeError(f"the run produced no {name}.json")
        return json.loads(path.read_text(encoding="utf-8"))  # type: ignore[no-any-return]

    try:
        yield str(out), result
    finally:
        os.environ.pop(variable, None)
        shutil.rmtree(out, ignore_errors=True)


def print_table(rows: list[list[str]], text_columns: tuple[int, ...]) -> None:
    """``rows`` (the first is the header) as a markdown table: ``text_columns`` left-aligned,
    the others (numbers) right-aligned."""
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for k, row in enumerate(rows):
        cells = [cell.ljust(w) if i in text_columns else cell.rjust(w)
                 for i, (cell, w) in enumerate(zip(row, widths, strict=True))]
        print("| " + " | ".join(cells) + " |")
        if k == 0:
            print("|" + "|".join(("-" * (w + 1) + ":") if i not in text_columns else "-" * (w + 2)
                                 for i, w in enumerate(widths)) + "|")


def write_results(path: Path, document: dict[str, Any], started: float) -> None:
    """Write a benchmark's JSON and say where, with the seconds since ``started`` (monotonic)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    print(f"\nwrote {path} ({time.monotonic() - started:.0f} s)")
