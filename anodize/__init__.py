"""anodize: run multiparty session types as monitored, isolated groups of roles.

    >>> import sessiontypes, anodize
    >>> ping = sessiontypes.loads("global P = A -> B : ping(int). B -> A : pong").globals["P"]
    >>> def a(ep): ep.send("B", "ping", 1); ep.recv("B")
    >>> def b(ep): ep.recv("A"); ep.send("A", "pong")
    >>> system = anodize.System(ping)
    >>> _ = system.group("g").role("A", a).role("B", b)
    >>> system.run(timeout=5).ok
    True

The public API is what this module exports (``__all__``) and :mod:`anodize.errors`; every
other module under ``anodize`` is private, whatever its name (tests/test_exports.py).
"""

from typing import Any

from ._isolation.sched import lower_thread_priority
from ._live.inputs import ClientInput, client_input
from ._live.server import LiveView, open_live_view
from ._recording.reader import RecordingError
from ._recording.replay_network import ReplayDivergenceError
from ._recording.run import Recording
from ._recording.selection import SelectionError
from ._ros.messages import RosDecodeError, RosEncodeError
from ._ros.rmw_zenoh import RmwZenohFormatError
from ._session import TIMEOUT, Endpoint, EndpointStatistics, Message, State
from ._session.logs import LogEntry
from ._supervision import (
    Dds,
    Group,
    GroupReport,
    GroupStatus,
    Inproc,
    Processes,
    RoleReport,
    RosBridge,
    RunReport,
    System,
    Transport,
    Zenoh,
)
from ._tools.config import ConfigError, SystemConfig, build_system, load_config
from ._tools.named import Finished, NamedSystem, Prepared
from ._transport.codec import DecodeError, EncodeError
from ._transport.links import PayloadError, SplitBrainError, StartBarrierError
from ._transport.qos_profiles import QosError
from ._transport.shm import RingAllocationError, RingFullError, StaleBufferError
from ._transport.zenoh.settings import ZenohTls
from .errors import (
    Action,
    AnodizeError,
    ConfigurationError,
    DeadlineMissedError,
    LinearityError,
    MemoryBoundError,
    MissingExtraError,
    ParameterError,
    PeerFailedError,
    ProtocolViolationError,
    RoleError,
    RoleStopped,
)
from .taps import ChannelTap

__all__ = [
    "System", "Group", "Endpoint", "Message", "RunReport", "RoleReport", "GroupReport",
    "AnodizeError", "ConfigurationError", "ParameterError",
    "ProtocolViolationError", "PeerFailedError", "MemoryBoundError",
    "LinearityError", "RoleStopped", "Action", "State", "GroupStatus",
    # Time constraints: a missed deadline or period, and the label of an `else timeout`.
    "DeadlineMissedError", "TIMEOUT",
    "Inproc", "Processes", "Dds", "Zenoh", "ZenohTls", "RosBridge", "ChannelTap", "Transport",
    # The taps a program can hand to System.run itself: a recording, the live view in Foxglove.
    "Recording", "open_live_view", "LiveView",
    "EndpointStatistics",
    # The roles' log records, as System.run(on_log=...) is handed them (docs/guide/logging.md).
    "LogEntry",
    # System files and named systems (`anodize run FILE`, `anodize run NAME`), as TinMan uses them.
    "SystemConfig", "load_config", "build_system", "NamedSystem", "Prepared", "Finished",
    # Helpers for roles: messages from live-view clients, a thread below its role's priority.
    "ClientInput", "client_input", "lower_thread_priority",
    # Every other error a user can meet, wherever it is raised.
    "RoleError", "MissingExtraError", "ConfigError", "EncodeError", "DecodeError", "PayloadError",
    "RingFullError", "RingAllocationError", "StaleBufferError", "RecordingError", "ReplayDivergenceError",
    "RosEncodeError", "RosDecodeError", "QosError", "SelectionError", "StartBarrierError", "SplitBrainError",
    "RmwZenohFormatError",
]

# Public names whose module needs an extra: imported on first use, so `import anodize` needs none
# (a missing extra raises MissingExtraError there). Reachable as attributes but not in __all__, so
# `from anodize import *` works without the extra too.
_NEEDS_AN_EXTRA: dict[str, tuple[str, str, str]] = {}  # none now: the barriers' errors live in _transport.links


def __getattr__(name: str) -> Any:
    if name not in _NEEDS_AN_EXTRA:
        raise AttributeError(f"module 'anodize' has no attribute {name!r}")
    import importlib

    from ._extras import import_extra

    module, needs, extra = _NEEDS_AN_EXTRA[name]
    import_extra(needs, extra, f"anodize.{name}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value
