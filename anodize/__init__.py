"""anodize: run multiparty session types as monitored, isolated groups of roles.

    >>> import sessiontypes, anodize
    >>> ping = sessiontypes.loads("global P = A -> B : ping(int). B -> A : pong").globals["P"]
    >>> def a(ep): ep.send("B", "ping", 1); ep.recv("B")
    >>> def b(ep): ep.recv("A"); ep.send("A", "pong")
    >>> system = anodize.System(ping)
    >>> _ = system.group("g").role("A", a).role("B", b)
    >>> system.run(timeout=5).ok
    True
"""

from .errors import (
    Action,
    AnodizeError,
    ConfigurationError,
    LinearityError,
    MemoryBoundError,
    PeerFailedError,
    ProtocolViolationError,
    RoleStopped,
)
from .session import Endpoint, Message, State
from .supervision import (
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
)
from .taps import ChannelTap

__all__ = [
    "System", "Group", "Endpoint", "Message", "RunReport", "RoleReport", "GroupReport",
    "AnodizeError", "ConfigurationError", "ProtocolViolationError", "PeerFailedError", "MemoryBoundError",
    "LinearityError", "RoleStopped", "Action", "State", "GroupStatus",
    "Inproc", "Processes", "Dds", "RosBridge", "ChannelTap",
]
