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

from .endpoint import Endpoint, Message, RoleStopped
from .errors import (
    Action,
    AnodizeError,
    LinearityError,
    MemoryBoundError,
    PeerFailedError,
    ProtocolViolationError,
)
from .group import Group
from .report import GroupReport, GroupStatus, RoleReport, RunReport
from .system import System
from .typed import State

__all__ = [
    "System", "Group", "Endpoint", "Message", "RunReport", "RoleReport", "GroupReport",
    "AnodizeError", "ProtocolViolationError", "PeerFailedError", "MemoryBoundError",
    "LinearityError", "RoleStopped", "Action", "State", "GroupStatus",
]
