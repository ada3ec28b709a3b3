"""sessiontypes: the ``.proto`` language of anodize.

Parse, check and project multiparty session types; print them canonically;
compile local types to state machines; generate typed endpoint code.

    >>> import sessiontypes
    >>> module = sessiontypes.loads("global P = A -> B : ping. B -> A : pong")
    >>> print(module.globals["P"].project("A"))
    !B(ping).?B(pong)
"""

import warnings
from typing import TYPE_CHECKING

from .check import ProtocolModule
from .constraints import Timing
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
from .sorts import Interaction, Sort

# Old names kept importable for one release, with a DeprecationWarning: old name -> new name.
_RENAMED = {"Message": "Interaction"}

__all__ = [
    "load", "loads", "read_source", "ProtocolModule", "GlobalType", "LocalType", "StateMachine", "Transition",
    "Interaction", "Sort", "Timing", "Location", "Diagnostic", "ProtocolError", "ProtocolSyntaxError",
    "ProtocolEncodingError", "ProtocolCheckError", "ProjectionError", "UnknownRoleError",
]


if not TYPE_CHECKING:  # hidden from type checkers: they then report the old name, and typos, as errors
    def __getattr__(name: str) -> object:
        """``sessiontypes.Message``: the old name of :class:`Interaction`, deprecated."""
        new = _RENAMED.get(name)
        if new is None:
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
        warnings.warn(f"sessiontypes.{name} is renamed sessiontypes.{new} (anodize.Message is a received "
                      "message, a different thing); the old name goes in the next release",
                      DeprecationWarning, stacklevel=2)
        return globals()[new]
