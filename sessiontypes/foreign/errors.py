"""The error for a Scribble or nuScr construct that the language has no counterpart for."""

from __future__ import annotations

from ..errors import Diagnostic, ProtocolError
from ..location import Location

__all__ = ["UnsupportedConstructError"]


class UnsupportedConstructError(ProtocolError):
    """Raised when a Scribble or nuScr file uses a construct outside the subset read.

    Attributes:
        location: where the construct starts.
        construct: what it is, in words (``"explicit connections ('connect')"``).
        reason: why it is not read, or "".
        source_line: the text of its line.
    """

    def __init__(self, location: Location, construct: str, reason: str = "",
                 source_line: str = "") -> None:
        self.location = location
        self.construct = construct
        self.reason = reason
        self.source_line = source_line
        super().__init__(str(self))

    @property
    def message(self) -> str:
        """The error text without the location and caret."""
        text = f"{self.construct} is not supported"
        return f"{text} ({self.reason})" if self.reason else text

    @property
    def diagnostics(self) -> tuple[Diagnostic, ...]:
        return (Diagnostic("error", self.location, self.message, self.source_line),)

    def __str__(self) -> str:
        return str(self.diagnostics[0])
