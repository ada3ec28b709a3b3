"""Groups: programs of one criticality (priority, memory bound, CPUs) and their roles."""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from decimal import Decimal
from enum import StrEnum
from typing import Any

from ..errors import AnodizeError, ConfigurationError

__all__ = ["Group", "FailurePolicy", "parse_memory", "resolve_function", "reference_of"]

_UNITS = {"": 1, "b": 1, "kb": 10**3, "mb": 10**6, "gb": 10**9,
          "kib": 2**10, "mib": 2**20, "gib": 2**30}



class FailurePolicy(StrEnum):
    """What the supervisor does when a group fails."""

    STOP = "stop"                # the group stops; its peers get PeerFailedError, the rest runs on
    RESTART = "restart"          # it starts again from its initial states (at most max_restarts times)
    STOP_SYSTEM = "stop-system"  # every group stops

    @classmethod
    def parse(cls, value: object, group: str) -> FailurePolicy:
        """The policy named ``value``.

        Raises:
            ConfigurationError: not a policy.
        """
        if isinstance(value, str):  # no policy's value is anything but a str
            try:
                return cls(value)
            except ValueError:
                pass
        raise ConfigurationError(f"group {group}: on_failure must be one of "
                                 f"{', '.join(p.value for p in cls)}, got {value!r}")


# The largest limit a cgroup (an int64 of bytes, page aligned) can hold: a bound
# above it could not be enforced, and is surely a typo.
MAX_MEMORY_BOUND = 2**63 - 2**12


def parse_memory(value: int | str | None) -> int | None:
    """``"64MiB"`` -> 67108864; ints are bytes; None stays None.

    Decimal arithmetic, so ``"1.5GiB"`` is exact and no size overflows a float.

    Raises:
        ConfigurationError: not a size, not positive, or above MAX_MEMORY_BOUND.
    """
    if value is None:
        return None
    if isinstance(value, int) and not isinstance(value, bool):
        size = value
    elif isinstance(value, str):
        match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([KkMmGg]i?[Bb]|[Bb])?\s*", value)
        if not match:
            raise ConfigurationError(f"memory bound {_shorten(value)}: expected a size such as 64MiB, "
                                     "512KiB or 1GB")
        number, unit = match.groups()
        size = int(Decimal(number) * _UNITS[(unit or "").lower()])
    else:
        raise ConfigurationError(f"memory bound {_shorten(value)}: expected a size such as 64MiB, 512KiB or 1GB")
    if size <= 0:
        raise ConfigurationError(f"memory bound {_shorten(value)}: expected a positive size")
    if size > MAX_MEMORY_BOUND:
        raise ConfigurationError(f"memory bound {_shorten(value)}: larger than any limit the kernel can "
                                 f"enforce ({MAX_MEMORY_BOUND} bytes, about 8 EiB)")
    return size


def _shorten(value: object) -> str:
    """``repr(value)``, with the middle of a very long one left out."""
    text = repr(value)
    return text if len(text) <= 60 else f"{text[:28]}...{text[-28:]} ({len(text)} characters)"


def resolve_function(reference: str) -> Callable[..., Any]:
    """Import the function named by ``"package.module:function"`` (or ``:Class.method``).

    Raises:
        AnodizeError: malformed, not importable, or not callable.
    """
    module_name, colon, qualified = reference.partition(":")
    if not colon or not module_name or not qualified:
        raise AnodizeError(f"role function {reference!r}: expected 'module:function'")
    try:
        value: Any = importlib.import_module(module_name)
        for part in qualified.split("."):
            value = getattr(value, part)
    except ImportError as error:
        raise AnodizeError(f"role function {reference!r}: cannot import {module_name}: {error}") from None
    except AttributeError:
        raise AnodizeError(f"role function {reference!r}: module {module_name} has no {qualified}") from None
    if not callable(value):
        raise AnodizeError(f"role function {reference!r} is not callable")
    return value  # type: ignore[no-any-return]


def reference_of(function: Callable[..., Any] | str) -> str:
    """``"module:qualname"`` for a module-level function (what another process can import).

    Raises:
        AnodizeError: a lambda, a nested function or another object with no import path.
    """
    if isinstance(function, str):
        return function
    module = getattr(function, "__module__", None)
    qualified = getattr(function, "__qualname__", None)
    if not module or not qualified or "<" in qualified:
        raise AnodizeError(
            f"role function {qualified or function!r} cannot run in another process: it has no "
            "import path (lambdas and nested functions are shared by closure); define it at "
            "module level or name it as 'module:function'")
    return f"{module}:{qualified}"


@dataclass
class Group:
    """A group of roles run with one priority, memory bound, CPU set and failure policy.

    Create with :meth:`anodize.System.group`; add roles with :meth:`role`.
    """

    name: str
    priority: int | None = None
    memory: int | None = None
    cpus: frozenset[int] | None = None
    on_failure: FailurePolicy = FailurePolicy.STOP
    max_restarts: int = 3
    host: str | None = None  # on Dds: the host it runs on (None: wherever the run is started)
    priority_inheritance: bool = True  # roles waiting on this group's roles lend them their priority
    nice: int | None = None  # ordinary scheduling at this nice value (only without a priority)
    namespace: str = ""  # the ROS namespace its roles' relative topic names resolve in ("": the system's)
    spin: int = 0  # nanoseconds a receiver may poll before it sleeps (0: never; anodize._transport.spin)
    roles: dict[str, Callable[..., Any] | str] = field(default_factory=dict)
    _system: Any = field(default=None, repr=False)

    def role(self, name: str, function: Callable[..., Any] | str) -> Group:
        """Run role ``name`` of the global type as ``function(endpoint)`` in this group.

        ``function`` takes an :class:`~anodize.Endpoint`, or the generated typed
        initial state (detected from its annotation); it may be given as
        ``"module:function"``. Returns the group, for chaining.

        Raises:
            ValueError: the global type has no such role, or it is already placed.
            AnodizeError: a ``"module:function"`` that cannot be imported.
        """
        self._system._place(self, name, function)
        self.roles[name] = function
        return self
