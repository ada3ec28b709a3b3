"""A meter of the work the reader and the checker do, for tests that count instead of timing.

Each pass adds how many units it did (node visits, merges, projected nodes,
translated interactions) under its own name when it finishes, so the meter
costs one call per pass, not one per node. Tests read :data:`METER` before
and after a check and assert that the work grows linearly with the
protocol's size (docs/decisions: references are shared, not inlined).
"""

from __future__ import annotations

import threading
from collections import Counter

__all__ = ["WorkMeter", "METER"]


class WorkMeter:
    """Units of work by pass, added from any thread (passes run on helper threads)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: Counter[str] = Counter()

    def add(self, kind: str, units: int) -> None:
        """Count ``units`` of work of the pass ``kind``."""
        with self._lock:
            self._counts[kind] += units

    def snapshot(self) -> Counter[str]:
        """The units counted so far, by pass (a copy)."""
        with self._lock:
            return Counter(self._counts)

    def total(self) -> int:
        """Every unit counted so far."""
        with self._lock:
            return sum(self._counts.values())


METER = WorkMeter()
