"""nuScr's refinement expressions (``x > 0 && y = x + 1``) read into the language's (:mod:`..constraints`).

nuScr writes a predicate inside a payload's braces (``x: int{x > 0}``) and inside a message's
annotation (``@"x > 0"``); both are read here, with :file:`nuscr_expr.lark` (nuScr's own
grammar of them), at the file position where the text starts, so every node and every syntax
error is located in the nuScr file. Besides :mod:`.read` this is the only module here that
imports lark, and no lark ``Tree`` or ``Token`` leaves it.

The operators become the language's: ``=`` is ``==``, ``<>`` is ``!=``, ``&&`` and ``||`` are
``and`` and ``or``, ``len(e)`` is ``len``; nuScr's precedence is kept by the tree, whatever
the language would make of the same text (``-x + 1`` is ``-(x + 1)``, ``a || b && c`` is
``(a || b) && c``, ``a < b < c`` is ``(a < b) < c``).
"""

from __future__ import annotations

import threading
from importlib import resources
from typing import Any

import lark

from ..constraints import Binary, Call, Compare, Expr, Number, Path, Text, Truth, Unary
from ..errors import ProtocolSyntaxError
from ..location import Location

__all__ = ["read_expression", "location_in"]

_OPERATORS = {"=": "==", "<>": "!=", "<": "<", ">": ">", "<=": "<=", ">=": ">="}
_WORDS = {
    "NAME": "a name", "INT": "an integer", "STRING": "a string", "LPAR": "'('", "RPAR": "')'",
    "COMPARE": "a comparison", "AMPAMP": "'&&'", "BARBAR": "'||'", "PLUS": "'+'", "MINUS": "'-'",
    "NOT": "'not'", "TRUE": "'true'", "FALSE": "'false'", "LEN": "'len'", "$END": "the end of the expression",
}
_lock = threading.Lock()
_parsers: list[lark.Lark] = []


def _parser() -> lark.Lark:
    with _lock:
        if not _parsers:
            grammar = resources.files(__package__).joinpath("nuscr_expr.lark")
            _parsers.append(lark.Lark(grammar.read_text(encoding="utf-8"), parser="lalr", lexer="contextual",
                                      maybe_placeholders=False))
        return _parsers[0]


def location_in(start: Location, text: str, offset: int) -> Location:
    """Where character ``offset`` of ``text`` is, ``text`` being written from ``start`` on."""
    before = text[:offset]
    newlines = before.count("\n")
    if not newlines:
        return Location(start.path, start.line, start.column + offset)
    return Location(start.path, start.line + newlines, offset - before.rfind("\n"))


def read_expression(text: str, start: Location, lines: tuple[str, ...]) -> Expr:
    """nuScr's expression ``text``, written from ``start`` on, as the language's.

    Raises:
        ProtocolSyntaxError: ``text`` is not a nuScr expression (located in the file).
    """
    try:
        tree = _parser().parse(text)
    except lark.exceptions.UnexpectedInput as error:
        raise _syntax_error(error, text, start, lines) from None
    return _Builder(text, start).expr(tree)


def _syntax_error(error: lark.exceptions.UnexpectedInput, text: str, start: Location,
                  lines: tuple[str, ...]) -> ProtocolSyntaxError:
    def line_of(location: Location) -> str:
        return lines[location.line - 1] if 0 < location.line <= len(lines) else ""

    if isinstance(error, lark.exceptions.UnexpectedCharacters):
        location = location_in(start, text, error.pos_in_stream or 0)
        return ProtocolSyntaxError(location, f"character {error.char!r}", _describe(error.allowed or ()),
                                   line_of(location))
    assert isinstance(error, lark.exceptions.UnexpectedToken), error
    token = error.token
    if token.type == "$END":
        location, got = location_in(start, text, len(text)), "the end of the expression"
    else:
        location, got = location_in(start, text, token.start_pos or 0), f"'{token}'"
    return ProtocolSyntaxError(location, got, _describe(error.expected), line_of(location))


def _describe(terminals: Any) -> list[str]:
    return sorted({_WORDS[name] for name in terminals if name in _WORDS})


class _Builder:
    """A parse tree of nuscr_expr.lark to an :data:`Expr`, each node at its first token."""

    def __init__(self, text: str, start: Location) -> None:
        self.text = text
        self.start = start

    def _at(self, item: lark.Tree[Any] | lark.Token) -> Location:
        while isinstance(item, lark.Tree):
            item = item.children[0]
        return location_in(self.start, self.text, item.start_pos or 0)

    def expr(self, node: lark.Tree[Any] | lark.Token) -> Expr:
        if isinstance(node, lark.Token):  # a parenthesised expression inlines to its token
            return self._token(node)
        kind, children, at = node.data, node.children, self._at(node)
        match kind:
            case "negation":
                return Unary("not", self.expr(children[1]), at)
            case "minus":
                return Unary("-", self.expr(children[1]), at)
            case "conjunction" | "disjunction":
                op = "and" if kind == "conjunction" else "or"
                return Binary(op, self.expr(children[0]), self.expr(children[2]), at)
            case "comparison":
                return Compare((_OPERATORS[str(children[1])],), (self.expr(children[0]), self.expr(children[2])), at)
            case "plus" | "difference":
                return Binary("+" if kind == "plus" else "-", self.expr(children[0]), self.expr(children[2]), at)
            case "length":
                return Call("len", (self.expr(children[2]),), at)
            case "integer" | "string" | "variable" | "true" | "false":
                token = children[0]
                assert isinstance(token, lark.Token), token
                return self._token(token)
        # LPAR expr RPAR kept as a tree: the expression inside
        inner = [child for child in children if not (isinstance(child, lark.Token) and child.type in ("LPAR", "RPAR"))]
        return self.expr(inner[0])

    def _token(self, token: lark.Token) -> Expr:
        at = location_in(self.start, self.text, token.start_pos or 0)
        match token.type:
            case "INT":
                return Number(int(token), at)
            case "STRING":
                return Text(str(token)[1:-1], at)
            case "TRUE" | "FALSE":
                return Truth(token.type == "TRUE", at)
        return Path((str(token),), at)
