"""What the benchmarks that run anodize systems share: settings handed to role functions in
group processes, and the results those roles write back."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["bench_env"]


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
