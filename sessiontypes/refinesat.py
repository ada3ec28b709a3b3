"""Cheap satisfiability of refinements: interval analysis of conjunctions of bounds.

A refinement (with the refinements of its message's fields) is read as a conjunction; each
conjunct that bounds one *term* (a path, ``abs(path)`` or ``len(path)``) by a constant
(``x > 5``, ``0 <= p <= 1``, ``abs(v) <= 1.5``, ``n != 3``) narrows that term's interval, and a
conjunct of constants is evaluated. The refinement is unsatisfiable when an interval empties
(an integer term's open bounds are rounded in; a nat, an ``abs`` and a ``len`` are at least 0;
``abs(v) <= h`` bounds ``v`` to ``[-h, h]``) or a constant conjunct is false. Anything else
(a disjunction, a relation between two paths, arithmetic on a path) is taken as satisfiable:
the analysis is sound for what it rejects, not complete.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TypeGuard

from .constraints import Binary, Call, Compare, Expr, Number, Path, Truth, Unary
from .location import NOWHERE, Location
from .refine import print_expr
from .refinetypes import Resolve

__all__ = ["conjuncts", "unsatisfiable"]

_FLIP = {"<": ">", "<=": ">=", ">": "<", ">=": "<=", "==": "==", "!=": "!="}


def conjuncts(expr: Expr | None) -> list[Expr]:
    """``expr``'s top-level ``and`` operands, left to right (none for None)."""
    if expr is None:
        return []
    if isinstance(expr, Binary) and expr.op == "and":
        return conjuncts(expr.left) + conjuncts(expr.right)
    return [expr]


def unsatisfiable(parts: list[Expr], resolve: Resolve, where: Location = NOWHERE) -> tuple[Location, str] | None:
    """Where and why the conjunction of ``parts`` can never hold, or None if not shown so.

    Args:
        parts: the conjuncts (see :func:`conjuncts`), all well typed.
        resolve: the paths' types (an int or nat term takes whole values; a nat is >= 0).
        where: the location for a conjunct built without one.
    """
    intervals: dict[str, _Interval] = {}
    for part in parts:
        location = part.location if part.location != NOWHERE else where
        constant = _fold(part)
        if constant is False:
            return location, f"unsatisfiable refinement: {print_expr(part)} never holds"
        if not isinstance(part, Compare):
            continue
        for index, op in enumerate(part.ops):
            left, right = part.operands[index], part.operands[index + 1]
            text = print_expr(Compare((op,), (left, right)))
            value = _fold(right)
            term, bound_op = left, op
            if not _is_number(value):
                term, bound_op, value = right, _FLIP[op], _fold(left)
            if not _is_number(value):
                continue
            problem = _narrow(intervals, term, bound_op, value, text, resolve)
            if problem is not None:
                return location, f"unsatisfiable refinement: {problem}"
    return None


def _is_number(value: object) -> TypeGuard[int | float]:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _fold(expr: Expr) -> object:
    """The value of a constant ``expr`` (no paths), or None."""
    match expr:
        case Number() | Truth():
            return expr.value
        case Unary(op="-"):
            inner = _fold(expr.operand)
            return -inner if _is_number(inner) else None
        case Binary(op="+" | "-" | "*" | "/" | "%"):
            left, right = _fold(expr.left), _fold(expr.right)
            if not (_is_number(left) and _is_number(right)):
                return None
            try:
                match expr.op:
                    case "+":
                        return left + right
                    case "-":
                        return left - right
                    case "*":
                        return left * right
                    case "/":
                        return left / right
                return left % right
            except (ZeroDivisionError, OverflowError):
                return None
        case Compare():
            values = [_fold(o) for o in expr.operands]
            if not all(_is_number(v) for v in values):
                return None
            return all(_holds(op, a, b) for op, a, b in zip(expr.ops, values, values[1:], strict=False))
    return None


def _holds(op: str, left: object, right: object) -> bool:
    assert isinstance(left, int | float) and isinstance(right, int | float)
    return {"==": left == right, "!=": left != right, "<": left < right, "<=": left <= right,
            ">": left > right, ">=": left >= right}[op]


@dataclass
class _Bound:
    value: float
    closed: bool
    text: str


@dataclass
class _Interval:
    integral: bool
    low: _Bound | None = None
    high: _Bound | None = None
    excluded: list[tuple[float, str]] = field(default_factory=list)

    def add(self, op: str, value: float, text: str) -> None:
        if op in (">", ">=", "=="):
            bound = _Bound(value, op != ">", text)
            if self.low is None or value > self.low.value or (value == self.low.value and not bound.closed):
                self.low = bound
        if op in ("<", "<=", "=="):
            bound = _Bound(value, op != "<", text)
            if self.high is None or value < self.high.value or (value == self.high.value and not bound.closed):
                self.high = bound
        if op == "!=":
            self.excluded.append((value, text))

    def empty_because(self) -> list[str] | None:
        """The texts of the bounds that leave no value, or None if some value is left."""
        if self.low is None or self.high is None:
            return None
        low, high = self.low.value, self.high.value
        if self.integral:
            low = math.ceil(low) if self.low.closed else math.floor(low) + 1
            high = math.floor(high) if self.high.closed else math.ceil(high) - 1
            empty = low > high
        else:
            empty = low > high or (low == high and not (self.low.closed and self.high.closed))
        texts = [self.low.text] + ([self.high.text] if self.high.text != self.low.text else [])
        if empty:
            return texts
        for point, text in self.excluded:
            if low == high == point:
                return [*texts, text]
        return None


def _narrow(intervals: dict[str, _Interval], term: Expr, op: str, value: float, text: str,
            resolve: Resolve) -> str | None:
    """Bound ``term op value``; the problem if ``term`` is left with no value."""
    key = _term(term)
    if key is None:
        return None
    interval = intervals.get(key)
    if interval is None:
        interval = intervals[key] = _new_interval(term, key, resolve)
    interval.add(op, value, text)
    empty = interval.empty_because()
    if empty is None and isinstance(term, Call) and term.function == "abs" and op in ("<", "<=", "=="):
        # abs(v) <= h: v is within [-h, h]
        inner = term.args[0]
        return _narrow_both(intervals, inner, op, value, text, resolve)
    if empty is None:
        return None
    return f"no value of {key} has {_join(empty)}"


def _narrow_both(intervals: dict[str, _Interval], term: Expr, op: str, value: float, text: str,
                 resolve: Resolve) -> str | None:
    low = _narrow(intervals, term, ">=" if op != "<" else ">", -value, text, resolve)
    return low if low is not None else _narrow(intervals, term, "<=" if op != "<" else "<", value, text, resolve)


def _term(expr: Expr) -> str | None:
    if isinstance(expr, Path):
        return print_expr(expr)
    if (isinstance(expr, Call) and expr.function in ("abs", "len") and len(expr.args) == 1
            and isinstance(expr.args[0], Path)):
        return print_expr(expr)
    return None


def _new_interval(term: Expr, key: str, resolve: Resolve) -> _Interval:
    if isinstance(term, Call):
        inner = term.args[0]
        assert isinstance(inner, Path)
        integral = term.function == "len" or resolve(inner)[0] in ("int", "nat")
        interval = _Interval(integral)
        interval.add(">=", 0, f"{key} >= 0")
        return interval
    assert isinstance(term, Path)
    kind = resolve(term)[0]
    interval = _Interval(kind in ("int", "nat"))
    if kind == "nat":
        interval.add(">=", 0, f"{key} >= 0 ({key} is a nat)")
    return interval


def _join(texts: list[str]) -> str:
    return texts[0] if len(texts) == 1 else f"{', '.join(texts[:-1])} and {texts[-1]}"
