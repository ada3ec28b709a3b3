"""What roles measured, left as one JSON file per role for the run's report.

Group processes cannot hand the launcher Python objects, and a group stopped by
its memory bound cannot hand over anything at all; so roles write their records
as they go (atomically: write, then rename) and the report reads what is there.

Only a launched run keeps records (:func:`records_folder`): a role function run on
its own, as ``anodize replay`` runs it against a recording, writes none, so that a
replay never overwrites the records of the run it replays (the default settings'
folder, ``out/tinman/records``, is that run's).
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path
from typing import Any

import numpy as np

from .settings import current, launched

__all__ = ["save_record", "load_records", "percentiles", "records_folder"]

MAX_RECORD_BYTES = 64 * 2**20  # a role's record is kilobytes; a larger one is not read


def records_folder() -> Path | None:
    """Where this run's roles leave their records; None when no launcher exported settings
    (a role replayed at a desk): then nothing is written."""
    return current().records if launched() else None


def save_record(name: str, data: dict[str, Any]) -> Path | None:
    """Write ``data`` as ``<records>/<name>.json``, replacing an older record whole (nothing,
    and None, outside a launched run: see :func:`records_folder`)."""
    folder = records_folder()
    if folder is None:
        return None
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.json"
    partial = folder / f".{name}.{os.getpid()}.partial"
    partial.write_text(json.dumps(data), encoding="utf-8")
    partial.replace(path)
    return path


def load_records(folder: str | Path) -> dict[str, dict[str, Any]]:
    """Every record in ``folder``: name -> data (unreadable files are skipped, not fatal).

    Roles write these, so they are read as untrusted input: a record that is not a regular
    file, is larger than ``MAX_RECORD_BYTES``, is not a JSON object or nests too deeply is skipped.
    """
    records: dict[str, dict[str, Any]] = {}
    for path in sorted(Path(folder).glob("*.json")):
        try:
            status = path.stat()
            if not stat.S_ISREG(status.st_mode) or status.st_size > MAX_RECORD_BYTES:
                continue
            data = json.loads(path.read_bytes()[:MAX_RECORD_BYTES + 1])  # it may have grown since
        except (OSError, ValueError, RecursionError):  # ValueError: not UTF-8, or not JSON
            continue
        if isinstance(data, dict):
            records[path.stem] = data
    return records


def percentiles(values: Any) -> dict[str, float | None]:
    """``p50``, ``p99``, ``max`` and ``mean`` of measurements (all None when there are none)."""
    values = np.asarray(values, dtype=float)
    if len(values) == 0:
        return {"p50": None, "p99": None, "max": None, "mean": None}
    return {"p50": round(float(np.percentile(values, 50)), 3), "p99": round(float(np.percentile(values, 99)), 3),
            "max": round(float(values.max()), 3), "mean": round(float(values.mean()), 3)}
