"""Time and value constraints on interactions (docs/language.md, "Time and value constraints").

Two kinds, each attached where it was written and carried unchanged from the global type to
every local type and state machine that owns it:

* :class:`Timing`, on an interaction (``A -> B : m within 100ms``, ``... every 20ms +- 2ms``,
  ``... within 100ms else timeout``): durations are whole nanoseconds, so that a print reads
  back to the same value and no float rounding decides a verdict.
* A *refinement*, a predicate over a payload (``Twist{abs(linear.x) <= 1.5}``,
  ``quote(price: int{price > 0})``): an :data:`Expr` tree of the small expression language
  below. It has no side effects and always terminates (no loops, no calls but the builtins).

This module holds the terms only; parsing is the grammar's, checking :mod:`sessiontypes.refine`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .location import NOWHERE, Location

__all__ = [
    "Timing", "NANOS", "format_duration",
    "Number", "Text", "Truth", "Path", "Unary", "Binary", "Compare", "Call", "Expr",
    "FUNCTIONS", "COMPARISONS",
]

# Nanoseconds per unit, as durations are written (``100ms``, ``1.5s``, ``250us``).
NANOS: dict[str, int] = {"ns": 1, "us": 1_000, "µs": 1_000, "ms": 1_000_000, "s": 1_000_000_000}


@dataclass(frozen=True, slots=True)
class Timing:
    """The time constraints of one interaction, each measured on one role's own clock.

    Attributes:
        within: a deadline in nanoseconds: the sender sends within it of its own previous
            action (or of its start), and the receiver expects the message within it of its own
            previous action; ``None`` if there is none.
        every: a period in nanoseconds: the sender's successive sends of this interaction are
            ``every +- jitter`` apart; ``None`` if there is none.
        jitter: how far from ``every`` a send may be, in nanoseconds (0 if not written).
        on_expiry: ``else timeout`` was written: when ``within`` passes with nothing arrived, the
            receiver takes a timeout (nobody is blamed) and waits again; the deadline is then the
            receiver's alone (the sender is not held to it).
    """

    within: int | None = None
    every: int | None = None
    jitter: int = 0
    on_expiry: bool = False
    location: Location = field(default=NOWHERE, compare=False)

    def __str__(self) -> str:
        """The canonical print: ``every T +- J within D else timeout``, each part if present."""
        parts: list[str] = []
        if self.every is not None:
            parts.append(f"every {format_duration(self.every)}")
            if self.jitter:
                parts.append(f"+- {format_duration(self.jitter)}")
        if self.within is not None:
            parts.append(f"within {format_duration(self.within)}")
            if self.on_expiry:
                parts.append("else timeout")
        return " ".join(parts)


def format_duration(nanos: int) -> str:
    """The shortest exact spelling: ``2s``, ``100ms``, ``1500us``, ``7ns``."""
    for unit in ("s", "ms", "us"):
        if nanos % NANOS[unit] == 0:
            return f"{nanos // NANOS[unit]}{unit}"
    return f"{nanos}ns"


# ---- the expression language of refinements --------------------------------------------

FUNCTIONS = ("abs", "min", "max", "len")
COMPARISONS = ("==", "!=", "<", "<=", ">", ">=")


@dataclass(frozen=True, slots=True)
class Number:
    """An integer or decimal literal (``1.5``, ``-2`` is a :class:`Unary` minus)."""

    value: int | float
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Text:
    """A string literal, ``"rgb8"``."""

    value: str
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Truth:
    """``true`` or ``false``."""

    value: bool
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Path:
    """A name and its field accesses: ``price``, ``linear.x``, ``header.stamp.sec``.

    The first name is, in this order: a field of the payload being checked (a record's field;
    for a declared sort, an attribute of the value), or a field of an earlier record payload
    the same role sent or received (the latest one).
    """

    parts: tuple[str, ...]
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Unary:
    """``not e`` or ``-e``."""

    op: str
    operand: Expr
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Binary:
    """``a and b``, ``a or b``, ``a + b``, ``a - b``, ``a * b``, ``a / b``, ``a % b``."""

    op: str
    left: Expr
    right: Expr
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Compare:
    """A comparison, possibly chained: ``0 <= p <= 1`` is ``ops=("<=", "<=")`` over three operands."""

    ops: tuple[str, ...]
    operands: tuple[Expr, ...]
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Call:
    """One of :data:`FUNCTIONS` applied: ``abs(x)``, ``min(a, b)``, ``len(path)``."""

    function: str
    args: tuple[Expr, ...]
    location: Location = field(default=NOWHERE, compare=False)


Expr = Number | Text | Truth | Path | Unary | Binary | Compare | Call
