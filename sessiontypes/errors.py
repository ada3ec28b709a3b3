"""The closed family of errors a protocol author can cause.

Every user error is a :class:`ProtocolError`; a bug in this package raises
anything else. Facts live in fields; the text is built in ``__str__`` in the
form ``path:line:col: error: <what>`` followed by the source line and a caret.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

from .location import Location

__all__ = [
    "Diagnostic",
    "ProtocolError",
    "ProtocolSyntaxError",
    "ProtocolEncodingError",
    "ProtocolCheckError",
    "ProjectionError",
    "ChoiceRaceError",
    "UnknownRoleError",
]

Severity = Literal["error", "warning"]


@dataclass(frozen=True, slots=True)
class Diagnostic:
    """One message about a place in a protocol source.

    Attributes:
        severity: ``"error"`` or ``"warning"``.
        location: where the problem is.
        message: what is wrong, in words (no location, no trailing period).
        source_line: the text of the offending line ("" when unknown).
        hint: how such a problem is usually fixed ("" when there is no general advice),
            shown on its own line after the caret.
    """

    severity: Severity
    location: Location
    message: str
    source_line: str = ""
    hint: str = ""

    def __str__(self) -> str:
        text = f"{self.location}: {self.severity}: {self.message}"
        if self.source_line and self.location.line > 0:
            text += f"\n{caret_block(self.source_line, self.location.column)}"
        return f"{text}\n    hint: {self.hint}" if self.hint else text


# Characters a terminal may break a line at or move the cursor for; shown as a space
# so that the caret stays under its column.
_LINE_BREAKS = str.maketrans(dict.fromkeys("\r\v\f\x1c\x1d\x1e\x85\u2028\u2029", " "))


SHOWN_WIDTH = 160  # characters of a source line shown around the caret (a line of megabytes is a hostile file's)


def caret_block(source_line: str, column: int) -> str:
    """Return ``source_line`` and below it a ``^`` under ``column`` (1-based); a line longer
    than ``SHOWN_WIDTH`` is shown as the window around the column, cut ends marked ``...``."""
    line = source_line.rstrip("\n").expandtabs(1).translate(_LINE_BREAKS)
    at = max(column - 1, 0)
    if len(line) > SHOWN_WIDTH:
        start = max(0, min(at - SHOWN_WIDTH // 2, len(line) - SHOWN_WIDTH))
        window = line[start:start + SHOWN_WIDTH]
        before, after = ("..." if start > 0 else ""), ("..." if start + SHOWN_WIDTH < len(line) else "")
        line, at = before + window + after, at - start + len(before)
    return f"    {line}\n    {' ' * at}^"


def shortened(text: str, width: int = 60) -> str:
    """``text``, or its start and end around ``...`` when longer than ``width`` (a token in a
    message: one of a hostile file's can be megabytes long)."""
    if len(text) <= width:
        return text
    half = (width - 3) // 2
    return f"{text[:half]}...{text[-half:]}"


class ProtocolError(Exception):
    """Root of every error caused by protocol text or its use (not a bug)."""


class ProtocolSyntaxError(ProtocolError):
    """Raised when protocol text does not follow the grammar.

    Attributes:
        location: where parsing stopped.
        got: a description of what was found there.
        expected: descriptions of what would have been accepted, sorted.
        source_line: the offending line of text.
        hint: an extra sentence for a common mistake, or "".
    """

    def __init__(
        self,
        location: Location,
        got: str,
        expected: Iterable[str],
        source_line: str = "",
        hint: str = "",
    ) -> None:
        self.location = location
        self.got = got
        self.expected = tuple(expected)
        self.source_line = source_line
        self.hint = hint
        super().__init__(str(self))

    @property
    def message(self) -> str:
        """The error text without the location and caret."""
        text = "syntax error"
        if self.expected:
            text += f"; expected {_one_of(self.expected)}"
        text += f", got {self.got}"
        if self.hint:
            text += f" ({self.hint})"
        return text

    @property
    def diagnostics(self) -> tuple[Diagnostic, ...]:
        return (Diagnostic("error", self.location, self.message, self.source_line),)

    def __str__(self) -> str:
        return str(self.diagnostics[0])


class ProtocolEncodingError(ProtocolError):
    """Raised when the bytes of a protocol file are not UTF-8 text.

    Attributes:
        location: where the first byte that cannot be decoded is; the column
            counts the characters before it on its line.
        byte: the value of that byte.
        source_line: its line, each byte that cannot be decoded shown as U+FFFD.
    """

    def __init__(self, location: Location, byte: int, source_line: str = "") -> None:
        self.location = location
        self.byte = byte
        self.source_line = source_line
        super().__init__(str(self))

    @property
    def message(self) -> str:
        """The error text without the location and caret."""
        return f"the file is not UTF-8 text: byte 0x{self.byte:02x} cannot be decoded"

    @property
    def diagnostics(self) -> tuple[Diagnostic, ...]:
        return (Diagnostic("error", self.location, self.message, self.source_line),)

    def __str__(self) -> str:
        return str(self.diagnostics[0])


class ProtocolCheckError(ProtocolError):
    """Raised when protocol text parses but is not well formed.

    ``str()`` shows every diagnostic, warnings included, in source order.

    Attributes:
        diagnostics: every error found (and any warnings), in source order.
    """

    def __init__(self, diagnostics: Iterable[Diagnostic]) -> None:
        self.diagnostics = tuple(diagnostics)
        super().__init__(str(self))

    @property
    def errors(self) -> tuple[Diagnostic, ...]:
        return tuple(d for d in self.diagnostics if d.severity == "error")

    def __str__(self) -> str:
        return "\n".join(str(d) for d in self.diagnostics)


class ProjectionError(ProtocolError):
    """Raised when a global type has no projection onto a role (merge fails).

    Attributes:
        protocol: the global type's name.
        role: the role being projected.
        location: the choice whose branches do not merge.
        left, right: the canonical prints of the two local behaviours.
        labels: the labels of the two branches that disagree.
        reason: why they do not merge.
        source_line: the text of the choice's line.
        chooser: the role that makes the choice ("" when unknown); with it the message
            ends with the usual fix, a message from the chooser to ``role`` in each branch.
    """

    def __init__(
        self,
        protocol: str,
        role: str,
        location: Location,
        labels: tuple[str, str],
        left: str,
        right: str,
        reason: str,
        source_line: str = "",
        chooser: str = "",
    ) -> None:
        self.protocol = protocol
        self.role = role
        self.location = location
        self.labels = labels
        self.left = left
        self.right = right
        self.reason = reason
        self.source_line = source_line
        self.chooser = chooser
        super().__init__(str(self))

    @property
    def message(self) -> str:
        first, second = self.labels
        return (
            f"global {self.protocol} is not projectable onto role {self.role}: "
            f"branches '{first}' and '{second}' give {self.role} different behaviours "
            f"that do not merge ({self.reason}): {self.left} versus {self.right}"
        )

    @property
    def hint(self) -> str:
        """The usual fix, in the syntax of the file: the chooser tells the role which branch it took."""
        if not self.chooser:
            return ""
        # 'B:x' names a routed branch by its receiver; the example message is named after its label.
        labels = list(dict.fromkeys(label.rpartition(":")[2] for label in self.labels if label != "?")) or ["done"]
        if len(labels) < len([label for label in self.labels if label != "?"]):  # 'B:x' and 'C:x': distinct names
            labels = [label.replace(":", "_") for label in self.labels]
        examples = " and ".join(f"`{_message_text(self.chooser, self.role, label, self.location.path)}`"
                                f"{f' in branch {label!r}' if len(labels) > 1 else ' in each branch'}"
                                for label in labels)
        return (f"{self.role} must learn which branch {self.chooser} chose before it acts differently: "
                f"in each branch, have {self.chooser} send {self.role} a message first, e.g. {examples}")

    @property
    def diagnostics(self) -> tuple[Diagnostic, ...]:
        return (Diagnostic("error", self.location, self.message, self.source_line, self.hint),)

    def __str__(self) -> str:
        return str(self.diagnostics[0])


class ChoiceRaceError(ProjectionError):
    """Raised when a role that learns a choice from the first of several peers' messages could be misled.

    The role's local type receives from several peers at one state and takes the
    branch of whichever message arrives first; in the branch of ``left`` (the
    receive that decides it), the peer of ``right`` can send ``right`` without
    waiting for ``left`` to be received, so the two may arrive in either order.

    Attributes (besides :class:`ProjectionError`'s):
        location: the interaction that sends ``right``.
        left: the deciding receive (``?A(m1)``); ``decided_at`` where it is written.
        right: the message that may overtake it (``?C(y)``).
        reason: the peers the role waits on (``A or C``).
    """

    def __init__(self, protocol: str, role: str, location: Location, left: str, right: str,
                 peers: str, decided_at: Location, source_line: str = "") -> None:
        self.decided_at = decided_at
        super().__init__(protocol, role, location, (left, right), left, right, peers, source_line)

    @property
    def message(self) -> str:
        sender, sent = _action_parts(self.right)
        _, deciding = _action_parts(self.left)
        where = self.decided_at
        return (
            f"global {self.protocol} is not projectable onto role {self.role}: {self.role} learns a "
            f"choice from whichever message arrives first from {self.reason}, but in the branch that "
            f"{self.left} (at {where.line}:{where.column}) decides, {sender} may send {sent} here "
            f"before {deciding} has reached {self.role}, so {self.role} could take {sent} first"
        )


def _message_text(sender: str, receiver: str, label: str, path: str) -> str:
    """One interaction ``sender -> receiver : label()`` as a file of ``path``'s language writes it."""
    if path.endswith((".scr", ".nuscr")):  # Scribble and nuScr: 'label() from A to B;'
        return f"{label}() from {sender} to {receiver};"
    return f"{sender} -> {receiver} : {label}()"


def _action_parts(action: str) -> tuple[str, str]:
    """``?C(y(str))`` -> ``("C", "y(str)")``."""
    peer, _, rest = action[1:].partition("(")
    return peer, rest[:-1]


def _one_of(items: tuple[str, ...]) -> str:
    if len(items) == 1:
        return items[0]
    return "one of " + ", ".join(items)


class UnknownRoleError(ProtocolError, KeyError):
    """Raised when a role is asked of a global type that does not have it.

    Attributes:
        protocol: the global type's name.
        role: the role asked for.
        roles: the roles the global type has.
    """

    def __init__(self, protocol: str, role: str, roles: tuple[str, ...]) -> None:
        self.protocol = protocol
        self.role = role
        self.roles = roles
        super().__init__(str(self))

    def __str__(self) -> str:
        return (f"error: global {self.protocol} has no role {self.role}; "
                f"expected one of {', '.join(self.roles) or '(no roles)'}")
