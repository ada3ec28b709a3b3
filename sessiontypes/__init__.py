"""sessiontypes: the ``.proto`` language of anodize.

Parse, check and project multiparty session types; print them canonically;
compile local types to state machines; generate typed endpoint code.

    >>> import sessiontypes
    >>> module = sessiontypes.loads("global P = A -> B : ping. B -> A : pong")
    >>> print(module.globals["P"].project("A"))
    !B(ping).?B(pong)
"""

from .check import ProtocolModule
from .declarations import GlobalType, LocalType
from .errors import (
    Diagnostic,
    ProjectionError,
    ProtocolCheckError,
    ProtocolEncodingError,
    ProtocolError,
    ProtocolSyntaxError,
    UnknownRoleError,
)
from .fsm import StateMachine, Transition
from .loader import load, loads, read_source
from .location import Location
from .sorts import Message, Sort

__all__ = [
    "load", "loads", "read_source", "ProtocolModule", "GlobalType", "LocalType", "StateMachine", "Transition",
    "Message", "Sort", "Location", "Diagnostic", "ProtocolError", "ProtocolSyntaxError",
    "ProtocolEncodingError", "ProtocolCheckError", "ProjectionError", "UnknownRoleError",
]
