"""Groups: programs of one criticality (priority, memory bound, CPUs) and their roles."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Group", "parse_memory"]

_UNITS = {"": 1, "b": 1, "kb": 10**3, "mb": 10**6, "gb": 10**9,
          "kib": 2**10, "mib": 2**20, "gib": 2**30}


def parse_memory(value: int | str | None) -> int | None:
    """``"64MiB"`` -> 67108864; ints are bytes; None stays None.

    Raises:
        ValueError: not a size.
    """
    if value is None or isinstance(value, int):
        return value
    match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([KkMmGg]i?[Bb]|[Bb])?\s*", value)
    if not match:
        raise ValueError(f"memory bound {value!r}: expected a size such as 64MiB, 512KiB or 1GB")
    number, unit = match.groups()
    return int(float(number) * _UNITS[(unit or "").lower()])


@dataclass
class Group:
    """A group of roles run with one priority, memory bound and CPU set.

    Create with :meth:`anodize.System.group`; add roles with :meth:`role`.
    """

    name: str
    priority: int | None = None
    memory: int | None = None
    cpus: frozenset[int] | None = None
    roles: dict[str, Callable[..., Any]] = field(default_factory=dict)
    _system: Any = field(default=None, repr=False)

    def role(self, name: str, function: Callable[..., Any]) -> Group:
        """Run role ``name`` of the global type as ``function(endpoint)`` in this group.

        ``function`` takes an :class:`~anodize.Endpoint`, or the generated typed
        initial state (detected from its annotation). Returns the group, for chaining.

        Raises:
            ValueError: the global type has no such role, or it is already placed.
        """
        self._system._place(self, name, function)
        self.roles[name] = function
        return self
