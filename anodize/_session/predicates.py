"""Refinements compiled to one Python function each: the monitor's fast check.

``sessiontypes.refine.compile_predicate`` is the reference: a closure tree that says why a
predicate is false or cannot be evaluated. Walking it costs about a microsecond and a half per
message; the function made here, from the same tree, costs a tenth of that. It answers only
"holds" (``True``) or "ask the reference" (anything else, or an exception): whenever it says
True, so does the reference, because every place where the reference insists on a ``bool``
(``and``, ``or``, ``not``, each comparison of a chain) is tested here with ``is True`` /
``is False``, never by Python's truthiness, and anything else raises (the answer is unknown).
Whenever it does not say True, the monitor asks the reference, whose verdict and reason stand.

No text of the protocol is evaluated: names become string constants handed in a namespace,
literals constants too; the source is built from the tree's shape alone.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Any

from sessiontypes.constraints import (
    COMPARISONS,
    FUNCTIONS,
    Binary,
    Call,
    Compare,
    Expr,
    Number,
    Path,
    Text,
    Truth,
    Unary,
)

__all__ = ["fast_predicate"]

FastCheck = Callable[[object, dict[str, object]], object]
_ARITHMETIC = frozenset({"+", "-", "*", "/", "%"})


def fast_predicate(expr: Expr, own_fields: Collection[str]) -> FastCheck:
    """A function ``(payload, earlier) -> True`` when ``expr`` holds (anything else: unknown).

    ``own_fields`` are the field names of the payload's record (a dict the sort's check has
    already accepted), read straight from it; other first names are looked up as the
    reference does (the payload, the earlier payloads, then an attribute).
    """
    builder = _Builder(frozenset(own_fields))
    body = builder.emit(expr)
    source = f"def check(p, e):\n    return {body}\n"
    namespace: dict[str, Any] = {"_head": _head, "_at": _at, "_unknown": _unknown,
                                 "_n": _number, "_same": _same_kind, "_ordered": _ordered,
                                 "abs": abs, "min": min, "max": max, "len": len, **builder.constants}
    exec(compile(source, "<refinement>", "exec"), namespace)  # built from the tree's shape alone, see above
    check: FastCheck = namespace["check"]
    return check


class _Builder:
    def __init__(self, own_fields: frozenset[str]) -> None:
        self.own_fields = own_fields
        self.constants: dict[str, object] = {}
        self.names = 0

    def constant(self, value: object) -> str:
        name = f"_k{len(self.constants)}"
        self.constants[name] = value
        return name

    def temporary(self) -> str:
        self.names += 1
        return f"_t{self.names}"

    def decide(self, test: str, if_true: str, if_false: str) -> str:
        """``if_true`` when ``test`` gives exactly True, ``if_false`` when exactly False, each
        evaluated only when chosen; anything else raises (the reference insists on a bool there)."""
        held = self.temporary()
        return f"(({if_true}) if ({held} := ({test})) is True else (({if_false}) if {held} is False else _unknown()))"

    def emit(self, expr: Expr) -> str:
        if isinstance(expr, Number | Text | Truth):
            return self.constant(expr.value)
        if isinstance(expr, Path):
            head = self.constant(expr.parts[0])
            text = f"p[{head}]" if expr.parts[0] in self.own_fields else f"_head(p, e, {head})"
            for part in expr.parts[1:]:
                text = f"_at({text}, {self.constant(part)})"
            return text
        if isinstance(expr, Unary):
            if expr.op == "not":
                return self.decide(self.emit(expr.operand), "False", "True")
            if expr.op != "-":
                raise ValueError(f"refinement: unknown operator {expr.op!r}")
            return f"(-{self.number(self.emit(expr.operand))})"
        if isinstance(expr, Binary):
            left, right = self.emit(expr.left), self.emit(expr.right)
            if expr.op == "and":  # L True: R's answer; L False: False; else unknown (None)
                return self.decide(left, self.decide(right, "True", "False"), "False")
            if expr.op == "or":
                return self.decide(left, "True", self.decide(right, "True", "False"))
            if expr.op not in _ARITHMETIC:
                raise ValueError(f"refinement: unknown operator {expr.op!r}")
            return f"({self.number(left)} {expr.op} {self.number(right)})"
        if isinstance(expr, Compare):
            if not set(expr.ops) <= set(COMPARISONS):
                raise ValueError(f"refinement: unknown comparison in {expr.ops!r}")
            operands = [self.emit(o) for o in expr.operands]
            held = [self.temporary() for _ in operands]
            kinds = [self.temporary() for _ in operands]
            # Each comparison must give True to go on, False ends it; anything else is unknown.
            text = "True"
            for k in reversed(range(len(expr.ops))):
                left = f"({kinds[k]} := type({held[k]} := ({operands[k]})))" if k == 0 else kinds[k]
                right = f"({kinds[k + 1]} := type({held[k + 1]} := ({operands[k + 1]})))"
                same = expr.ops[k] in ("==", "!=")
                comparable = _same_kinds(kinds[k], kinds[k + 1]) if same else _ordered_kinds(kinds[k], kinds[k + 1])
                # The operands first (left, then right), then their kinds, then the comparison.
                test = (f"(({held[k]} {expr.ops[k]} {held[k + 1]}) if (({left}, {right}) and ({comparable}))"
                        " else _unknown())")
                text = self.decide(test, text, "False")
            return text
        assert isinstance(expr, Call)
        if expr.function not in FUNCTIONS:
            raise ValueError(f"refinement: unknown function {expr.function!r}")
        if expr.function == "len":
            return f"len({', '.join(self.emit(a) for a in expr.args)})"
        return f"{expr.function}({', '.join(self.number(self.emit(a)) for a in expr.args)})"

    def number(self, text: str) -> str:
        """``text``'s value if arithmetic takes it in the reference (an int or a float, by the
        exact type: a bool is neither), else unknown: ``_number`` inlined, no call."""
        value, kind = self.temporary(), self.temporary()
        return f"({value} if (({kind} := type({value} := ({text}))) is float or {kind} is int) else _unknown())"


class _UnknownError(Exception):
    """Not a bool where the reference wants one: the reference decides (and says why)."""


def _unknown() -> bool:
    raise _UnknownError


# The kinds the reference's operators take (sessiontypes.refine): a number is an int or a float
# here (a bool is none; numpy's scalars and other reals are left to the reference).
_NUMBERS = (int, float)
_ORDERED = (int, float, str, bytes)


def _number(value: object) -> object:
    """``value`` if arithmetic takes it in the reference, else unknown."""
    if type(value) in _NUMBERS:
        return value
    raise _UnknownError


def _same_kind(left: object, right: object) -> object:
    """``left``, if ``==``/``!=`` compares it with ``right`` in the reference (one kind), else unknown."""
    kinds = type(left), type(right)
    if (kinds[0] is kinds[1] and kinds[0] in (bool, str, bytes)) or (kinds[0] in _NUMBERS and kinds[1] in _NUMBERS):
        return left
    raise _UnknownError


def _ordered(left: object, right: object) -> object:
    """``left``, if ``<`` and the like compare it with ``right`` in the reference, else unknown."""
    kinds = type(left), type(right)
    if (kinds[0] in _NUMBERS and kinds[1] in _NUMBERS) or (kinds[0] is kinds[1] and kinds[0] in _ORDERED):
        return left
    raise _UnknownError


def _same_kinds(left: str, right: str) -> str:
    """Source testing that kinds ``left`` and ``right`` (names of types) compare with ``==`` and
    ``!=`` in the reference: :func:`_same_kind` inlined, by identity."""
    return (f"({left} is {right} and ({left} is bool or {left} is str or {left} is bytes)) or "
            f"(({left} is int or {left} is float) and ({right} is int or {right} is float))")


def _ordered_kinds(left: str, right: str) -> str:
    """Source testing that kinds ``left`` and ``right`` compare with ``<`` and the like in the
    reference: :func:`_ordered` inlined, by identity."""
    return (f"(({left} is int or {left} is float) and ({right} is int or {right} is float)) or "
            f"({left} is {right} and ({left} is str or {left} is bytes))")


def _head(payload: object, earlier: dict[str, object], name: str) -> object:
    """A path's first name, in the reference's order: the payload's field, an earlier payload's,
    an attribute of the payload."""
    if isinstance(payload, dict) and name in payload:
        return payload[name]
    if name in earlier:
        return earlier[name]
    return getattr(payload, name)


def _at(value: object, name: str) -> object:
    """A field of a value: a dict's item, else an attribute (as the reference reads it)."""
    return value[name] if isinstance(value, dict) else getattr(value, name)
