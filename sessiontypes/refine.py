"""Refinements: printing and evaluating the predicates of :mod:`sessiontypes.constraints`.

A predicate is evaluated by a closure tree built once per predicate (:func:`compile_predicate`):
no text is evaluated and nothing but the payload's own attribute reads can run code. Every
failure to evaluate (a missing field, a division by zero, an operator the values do not take)
makes the predicate false, with the reason saying why: a monitor blames, it never crashes.

The operators take what :mod:`sessiontypes.refinetypes` lets them take, checked again on the
values (an attribute of a declared sort is only known at run time): arithmetic, unary minus,
``abs``, ``min`` and ``max`` take numbers, and a bool is no number (``true + 1`` fails, though
Python would say 2); ``and``, ``or`` and ``not`` take bools (no truthiness); ``==`` and ``!=``
compare two values of one kind (``1 == true`` fails rather than being true), ``<`` and the
others two numbers, two strs or two bytes; ``len`` takes anything with a length but a number
or a bool. Other values (a list, a message) compare with ``==`` among themselves only.
"""

from __future__ import annotations

import numbers
import operator
from collections.abc import Callable, Mapping
from typing import Any

from .constraints import Binary, Call, Compare, Expr, Number, Path, Text, Truth, Unary

__all__ = ["print_expr", "compile_predicate", "Predicate", "conjunction", "EvaluationError"]

# Binding strength, loosest first, as in Python.
_STRENGTH = {"or": 1, "and": 2, "not": 3, "compare": 4, "+": 5, "-": 5, "*": 6, "/": 6, "%": 6, "neg": 7}


def print_expr(expr: Expr) -> str:
    """The canonical print: minimal parentheses, one space around each binary operator."""
    return _print(expr, 0)


def _print(expr: Expr, context: int) -> str:
    text, strength = _print_bare(expr)
    return f"({text})" if strength < context else text


def _print_bare(expr: Expr) -> tuple[str, int]:
    if isinstance(expr, Number):
        return repr(expr.value), 9
    if isinstance(expr, Text):
        escaped = expr.value.replace("\\", "\\\\").replace('"', '\\"')
        return f'"{escaped}"', 9
    if isinstance(expr, Truth):
        return ("true" if expr.value else "false"), 9
    if isinstance(expr, Path):
        return ".".join(expr.parts), 9
    if isinstance(expr, Call):
        return f"{expr.function}({', '.join(_print(a, 0) for a in expr.args)})", 9
    if isinstance(expr, Unary):
        if expr.op == "not":
            return f"not {_print(expr.operand, _STRENGTH['not'])}", _STRENGTH["not"]
        return f"-{_print(expr.operand, _STRENGTH['neg'])}", _STRENGTH["neg"]
    if isinstance(expr, Compare):
        strength = _STRENGTH["compare"]
        parts = [_print(expr.operands[0], strength + 1)]
        for op, operand in zip(expr.ops, expr.operands[1:], strict=True):
            parts.append(f"{op} {_print(operand, strength + 1)}")
        return " ".join(parts), strength
    strength = _STRENGTH[expr.op]
    # Left-associative: the right operand of a - b - c's kind needs parentheses at equal strength.
    left = _print(expr.left, strength)
    right = _print(expr.right, strength + 1)
    return f"{left} {expr.op} {right}", strength


class EvaluationError(Exception):
    """A predicate could not be evaluated on a value (it then counts as false)."""


Predicate = Callable[[object, Mapping[str, object]], "str | None"]
_Eval = Callable[[object, Mapping[str, object]], Any]

_ARITHMETIC: dict[str, Callable[[Any, Any], Any]] = {
    "+": operator.add, "-": operator.sub, "*": operator.mul, "/": operator.truediv, "%": operator.mod,
}
_FUNCTIONS: dict[str, Callable[..., Any]] = {"abs": abs, "min": min, "max": max}
_COMPARE: dict[str, Callable[[Any, Any], Any]] = {
    "==": operator.eq, "!=": operator.ne, "<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge,
}


def _kind(value: object) -> str:
    """The kind an operator sees: number (a real, not a bool), bool, str, bytes, or other."""
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, numbers.Real):
        return "number"
    if isinstance(value, str):
        return "str"
    if isinstance(value, bytes):
        return "bytes"
    return "other"


def conjunction(parts: list[Expr]) -> Expr | None:
    """``parts`` joined by ``and`` (None for none)."""
    if not parts:
        return None
    joined = parts[0]
    for part in parts[1:]:
        joined = Binary("and", joined, part, part.location)
    return joined


def compile_predicate(expr: Expr) -> Predicate:
    """A function ``(payload, earlier) -> None | reason``: None when ``expr`` holds of
    ``payload``, else why not. ``earlier`` maps the names of earlier payloads' fields to their
    values (the latest); a path's first name is looked up in the payload first."""
    evaluate = _compile(expr)
    text = print_expr(expr)

    def check(payload: object, earlier: Mapping[str, object]) -> str | None:
        try:
            value = evaluate(payload, earlier)
        except EvaluationError as error:
            return f"refinement {{{text}}} cannot be evaluated: {error}"
        if value is True:
            return None
        if value is False:
            return f"refinement {{{text}}} is false"
        return f"refinement {{{text}}} gives {type(value).__name__} {value!r}, not a bool"

    return check


def _compile(expr: Expr) -> _Eval:
    if isinstance(expr, Number | Text | Truth):
        value = expr.value
        return lambda payload, earlier: value
    if isinstance(expr, Path):
        return _compile_path(expr.parts)
    if isinstance(expr, Unary):
        operand = _compile(expr.operand)
        if expr.op == "not":
            return lambda payload, earlier: not _truth(operand(payload, earlier), "not")
        return lambda payload, earlier: _apply(operator.neg, "-", *_numbers("-", operand(payload, earlier)))
    if isinstance(expr, Binary):
        left, right = _compile(expr.left), _compile(expr.right)
        if expr.op == "and":
            return lambda payload, earlier: (_truth(left(payload, earlier), "and")
                                             and _truth(right(payload, earlier), "and"))
        if expr.op == "or":
            return lambda payload, earlier: (_truth(left(payload, earlier), "or")
                                             or _truth(right(payload, earlier), "or"))
        function, op = _ARITHMETIC[expr.op], expr.op
        return lambda payload, earlier: _apply(
            function, op, *_numbers(op, left(payload, earlier), right(payload, earlier)))
    if isinstance(expr, Compare):
        operands = [_compile(o) for o in expr.operands]
        tests = [(_COMPARE[op], op) for op in expr.ops]

        def compare(payload: object, earlier: Mapping[str, object]) -> bool:
            left = operands[0](payload, earlier)
            for (test, op), right_of in zip(tests, operands[1:], strict=True):
                right = right_of(payload, earlier)
                if not _compare(test, op, left, right):
                    return False
                left = right
            return True

        return compare
    assert isinstance(expr, Call)
    args = [_compile(a) for a in expr.args]
    name = expr.function
    if name == "len":
        return lambda payload, earlier: _apply(len, name, *_sized(name, *[a(payload, earlier) for a in args]))
    function = _FUNCTIONS[name]
    return lambda payload, earlier: _apply(function, name, *_numbers(name, *[a(payload, earlier) for a in args]))


def _compile_path(parts: tuple[str, ...]) -> _Eval:
    head, rest = parts[0], parts[1:]

    def read(payload: object, earlier: Mapping[str, object]) -> Any:
        if isinstance(payload, dict) and head in payload:
            value = payload[head]
        elif head in earlier:
            value = earlier[head]
        elif not isinstance(payload, dict) and hasattr(payload, head):
            value = getattr(payload, head)
        else:
            raise EvaluationError(f"no field {head}")
        for name in rest:
            if isinstance(value, dict) and name in value:
                value = value[name]
            elif not isinstance(value, dict) and hasattr(value, name):
                value = getattr(value, name)
            else:
                raise EvaluationError(f"{type(value).__name__} has no field {name}")
        return value

    return read


def _truth(value: object, op: str) -> bool:
    if isinstance(value, bool):
        return value
    raise EvaluationError(f"{op} takes bools, not {type(value).__name__} {value!r}")


def _apply(function: Callable[..., Any], op: str, *values: object) -> Any:
    try:
        return function(*values)
    except ZeroDivisionError:
        raise EvaluationError(f"{op} divides by zero") from None
    except (TypeError, ValueError, OverflowError) as error:
        kinds = ", ".join(type(v).__name__ for v in values)
        raise EvaluationError(f"{op} cannot take {kinds} ({error})") from None


def _numbers(op: str, *values: object) -> tuple[object, ...]:
    for value in values:
        if _kind(value) != "number":
            raise EvaluationError(f"{op} takes numbers, not {type(value).__name__} {value!r}")
    return values


def _sized(op: str, *values: object) -> tuple[object, ...]:
    for value in values:
        if _kind(value) in ("number", "bool"):
            raise EvaluationError(f"{op} takes a str, bytes or a sequence, not {type(value).__name__} {value!r}")
    return values


def _compare(test: Callable[[Any, Any], Any], op: str, left: object, right: object) -> bool:
    """``left op right`` on two values of kinds the comparison takes (as a bool: a numpy
    scalar's comparison gives a numpy bool)."""
    kinds = (_kind(left), _kind(right))
    same = kinds[0] == kinds[1]
    allowed = same if op in ("==", "!=") else same and kinds[0] in ("number", "str", "bytes")
    if not allowed:
        raise EvaluationError(f"{op} cannot compare {type(left).__name__} {left!r} "
                              f"with {type(right).__name__} {right!r}")
    result = _apply(test, op, left, right)
    try:
        return bool(result)
    except (TypeError, ValueError) as error:  # an array's elementwise ==
        raise EvaluationError(f"{op} gives {type(result).__name__}, not a bool ({error})") from None
