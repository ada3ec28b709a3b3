"""The types of refinement expressions: which operator takes which values (docs/language.md).

The kinds are the builtin sorts' (``int``, ``nat``, ``float``, ``bool``, ``str``, ``bytes``)
and *unknown*: an attribute of a declared sort's value (``Twist{abs(linear.x) <= 1.5}``),
whose type only the bound class knows; an unknown operand is accepted by every operator and
checked at run time. The rules:

* ``and``, ``or``, ``not`` take bools; a refinement as a whole is a bool;
* ``+ - * / %`` and unary ``-`` take numbers (``int``, ``nat``, ``float`` mix; a bool is no
  number, so ``true + 1`` is an error here and false at run time);
* ``==`` and ``!=`` compare two values of one kind (two numbers, two bools, two strs, two bytes);
* ``< <= > >=`` compare two numbers, two strs or two bytes;
* ``abs(n)``; ``min``/``max`` of two or more numbers; ``len`` of a str or bytes.
"""

from __future__ import annotations

from collections.abc import Callable

from .constraints import COMPARISONS, FUNCTIONS, Binary, Call, Compare, Expr, Number, Path, Text, Truth, Unary
from .location import NOWHERE, Location
from .refine import print_expr

__all__ = ["Resolve", "type_errors", "article", "NUMBERS"]

NUMBERS = frozenset({"int", "nat", "float"})
_ARITHMETIC = frozenset({"+", "-", "*", "/", "%"})
_ERROR = "<error>"  # the type of a part already reported: its users report nothing more

Resolve = Callable[[Path], "tuple[str | None, str | None]"]
"""A path's type (``None``: unknown) and, if it names nothing in scope, the problem instead."""


def article(kind: str) -> str:
    """``an int``, ``a str``, ``bytes``: a kind as a message says it."""
    if kind == "bytes":
        return "bytes"
    return f"an {kind}" if kind[:1] in "aeiou" else f"a {kind}"


def type_errors(expr: Expr, resolve: Resolve, where: Location = NOWHERE) -> list[tuple[Location, str]]:
    """The name and type errors of the predicate ``expr``, each located (``where`` for a node without).

    Args:
        expr: a refinement.
        resolve: what each path's first name means where ``expr`` is written.
        where: the location to report at when a node was built without one.
    """
    typer = _Typer(resolve, where)
    result = typer.type_of(expr)
    if result not in (None, _ERROR, "bool"):
        typer.error(expr, f"a refinement is a bool, got {result} ({print_expr(expr)})")
    return typer.errors


class _Typer:
    def __init__(self, resolve: Resolve, where: Location) -> None:
        self.resolve = resolve
        self.where = where
        self.errors: list[tuple[Location, str]] = []

    def error(self, expr: Expr, message: str) -> str:
        location = expr.location if expr.location != NOWHERE else self.where
        self.errors.append((location, message))
        return _ERROR

    def type_of(self, expr: Expr) -> str | None:
        """The type of ``expr``: a kind, None (unknown) or _ERROR (reported)."""
        match expr:
            case Number():
                return "float" if isinstance(expr.value, float) else "int"
            case Text():
                return "str"
            case Truth():
                return "bool"
            case Path():
                kind, problem = self.resolve(expr)
                return self.error(expr, problem) if problem is not None else kind
            case Unary():
                return self._unary(expr)
            case Binary():
                return self._binary(expr)
            case Compare():
                return self._compare(expr)
            case Call():
                return self._call(expr)
        raise AssertionError(expr)  # pragma: no cover - Expr is closed

    def _expect(self, expr: Expr, kind: str | None, allowed: frozenset[str], message: str) -> bool:
        """Report ``message`` (with what ``expr`` is) unless ``kind`` is allowed, unknown or reported."""
        if kind is None or kind == _ERROR or kind in allowed:
            return kind != _ERROR
        self.error(expr, f"{message}, got {kind} ({print_expr(expr)})")
        return False

    def _unary(self, expr: Unary) -> str | None:
        kind = self.type_of(expr.operand)
        if expr.op == "not":
            ok = self._expect(expr.operand, kind, frozenset({"bool"}), "`not` takes a bool")
            return "bool" if ok else _ERROR
        if expr.op != "-":
            return self.error(expr, f"unknown operator {expr.op}; expected not or -")
        if not self._expect(expr.operand, kind, NUMBERS, "`-` takes a number"):
            return _ERROR
        return None if kind is None else ("float" if kind == "float" else "int")

    def _binary(self, expr: Binary) -> str | None:
        left, right = self.type_of(expr.left), self.type_of(expr.right)
        if expr.op in ("and", "or"):
            ok = self._expect(expr.left, left, frozenset({"bool"}), f"`{expr.op}` takes bools")
            ok = self._expect(expr.right, right, frozenset({"bool"}), f"`{expr.op}` takes bools") and ok
            return "bool" if ok else _ERROR
        if expr.op not in _ARITHMETIC:
            return self.error(expr, f"unknown operator {expr.op}; expected one of and, or, + - * / %")
        ok = self._expect(expr.left, left, NUMBERS, f"`{expr.op}` takes numbers")
        ok = self._expect(expr.right, right, NUMBERS, f"`{expr.op}` takes numbers") and ok
        if not ok:
            return _ERROR
        return _number_result((left, right), float_always=expr.op == "/")

    def _compare(self, expr: Compare) -> str | None:
        kinds = [self.type_of(operand) for operand in expr.operands]
        ok = True
        for index, op in enumerate(expr.ops):
            left, right = kinds[index], kinds[index + 1]
            if op not in COMPARISONS:
                self.error(expr, f"unknown comparison {op}; expected one of {' '.join(COMPARISONS)}")
                ok = False
            elif left is None or right is None or _ERROR in (left, right):
                ok = ok and _ERROR not in (left, right)
            elif not _comparable(op, left, right):
                pair = Compare((op,), (expr.operands[index], expr.operands[index + 1]))
                takes = ("compares two values of one kind" if op in ("==", "!=")
                         else "compares two numbers, two strs or two bytes")
                self.error(expr, f"`{op}` {takes}, got {left} and {right} ({print_expr(pair)})")
                ok = False
        return "bool" if ok else _ERROR

    def _call(self, expr: Call) -> str | None:
        kinds = [self.type_of(arg) for arg in expr.args]
        name, count = expr.function, len(expr.args)
        if name not in FUNCTIONS:
            return self.error(expr, f"unknown function {name}; expected one of {', '.join(sorted(FUNCTIONS))}")
        if name in ("abs", "len") and count != 1:
            what = "one number" if name == "abs" else "one str or bytes"
            return self.error(expr, f"`{name}` takes {what}, got {count} arguments")
        if name in ("min", "max") and count < 2:
            return self.error(expr, f"`{name}` takes two or more numbers, got {count} argument"
                                    f"{'' if count == 1 else 's'}")
        if name == "len":
            ok = self._expect(expr.args[0], kinds[0], frozenset({"str", "bytes"}), "`len` takes a str or bytes")
            return "int" if ok else _ERROR
        message = "`abs` takes a number" if name == "abs" else f"`{name}` takes numbers"
        ok = True
        for arg, kind in zip(expr.args, kinds, strict=True):  # every argument reported, not the first
            ok = self._expect(arg, kind, NUMBERS, message) and ok
        if not ok:
            return _ERROR
        return _number_result(tuple(kinds), float_always=False)


def _number_result(kinds: tuple[str | None, ...], *, float_always: bool) -> str | None:
    if None in kinds:
        return None
    return "float" if float_always or "float" in kinds else "int"


def _comparable(op: str, left: str, right: str) -> bool:
    same = (left in NUMBERS and right in NUMBERS) or left == right
    if op in ("==", "!="):
        return same
    return same and left != "bool"
