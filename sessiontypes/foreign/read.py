"""Scribble and nuScr text to :mod:`.tree` (the only module here that imports lark).

Each language has its grammar (``scribble.lark``, ``nuscr.lark``); one walk
turns either parse tree into the shared tree. A construct outside the subset
read parses, and the walk refuses it with an :class:`UnsupportedConstructError`
located at its first token; no lark ``Tree`` or ``Token`` leaves this module.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from importlib import resources
from typing import Any, NoReturn

import lark

from ..constraints import Expr
from ..errors import Diagnostic, ProtocolCheckError, ProtocolSyntaxError
from ..location import Location
from ..syntax import Name
from . import tree as t
from .errors import UnsupportedConstructError
from .refinements import location_in, read_expression

__all__ = ["MAX_NESTING", "read_module"]

# How deeply choice, rec and par blocks may nest. Far beyond what anyone writes;
# the bound keeps the reader's and the checker's recursion within its stack.
MAX_NESTING = 10_000

_GRAMMARS = {"scribble": "scribble.lark", "nuscr": "nuscr.lark"}
_parsers: dict[str, lark.Lark] = {}
_lock = threading.Lock()

# What a terminal is called in a syntax error.
_WORDS = {
    "NAME": "a name", "STRING": "a string", "LPAR": "'('", "RPAR": "')'", "LBRACE": "'{'",
    "RBRACE": "'}'", "COMMA": "','", "SEMICOLON": "';'", "COLON": "':'", "DOT": "'.'",
    "LT": "'<'", "MORETHAN": "'>'", "AT_SIGN": "'@'", "$END": "end of file",
    "REFINEMENT": "a refinement '{...}'", "STATE": "'[...]'",
}

# nuScr's pragmas (nuscr/nuscr lib/utils/pragma.ml). Refinements are always checked on both
# sides and for satisfiability where that is cheap, so the validation pragmas change nothing.
_PRAGMAS = frozenset({
    "NestedProtocols", "ShowPragmas", "PrintUsage", "RefinementTypes", "SenderValidateRefinements",
    "ReceiverValidateRefinements", "ValidateRefinementSatisfiability", "ValidateRefinementProgress",
})


def _parser(language: str) -> lark.Lark:
    with _lock:
        if language not in _parsers:
            grammar = resources.files(__package__).joinpath(_GRAMMARS[language])
            _parsers[language] = lark.Lark(grammar.read_text(encoding="utf-8"), parser="lalr",
                                           lexer="contextual", propagate_positions=False,
                                           maybe_placeholders=False)
        return _parsers[language]


def read_module(text: str, path: str, language: str, lines: tuple[str, ...]) -> t.ForeignModule:
    """Parse ``text``, a Scribble (``language="scribble"``) or nuScr file.

    Raises:
        ProtocolSyntaxError: the text does not follow the language's grammar.
        UnsupportedConstructError: it uses a construct outside the subset read.
    """
    try:
        parsed = _parser(language).parse(text)
    except lark.exceptions.UnexpectedInput as error:
        raise _syntax_error(error, path, lines) from None
    _check_nesting(parsed, path, lines)
    return _Reader(path, lines, language).module(parsed)


def _check_nesting(root: lark.Tree[Any], path: str, lines: tuple[str, ...]) -> None:
    """Refuse blocks nested deeper than :data:`MAX_NESTING`, at the first block too deep.

    The walks after this one recurse once per level of nesting (never per
    interaction of a sequence); this walk, iterative, bounds them.
    """
    stack: list[tuple[lark.Tree[Any], int]] = [(root, 0)]
    while stack:
        node, depth = stack.pop()
        if node.data in ("block", "body"):
            depth += 1
            if depth > MAX_NESTING:
                brace = node.children[0]
                assert isinstance(brace, lark.Token), brace
                location = Location(path, brace.line or 0, brace.column or 0)
                line = lines[location.line - 1] if 0 < location.line <= len(lines) else ""
                raise ProtocolCheckError([Diagnostic(
                    "error", location, f"blocks nested more than {MAX_NESTING} deep (a choice, rec or "
                    f"par inside another, {MAX_NESTING} times); at most {MAX_NESTING} levels are read",
                    line)])
        if node.data in ("protocol", "nested"):
            depth -= 1  # its own body is not nested in anything
        stack.extend((child, depth) for child in node.children if isinstance(child, lark.Tree))


def _syntax_error(error: lark.exceptions.UnexpectedInput, path: str,
                  lines: tuple[str, ...]) -> ProtocolSyntaxError:
    def line_of(number: int) -> str:
        return lines[number - 1] if 0 < number <= len(lines) else ""

    if isinstance(error, lark.exceptions.UnexpectedCharacters):
        char = error.char
        return ProtocolSyntaxError(Location(path, error.line, error.column), f"character {char!r}",
                                   _describe(error.allowed or ()), line_of(error.line))
    assert isinstance(error, lark.exceptions.UnexpectedToken), error
    token = error.token
    if token.type == "$END":
        last = len(lines) or 1
        location, got = Location(path, last, len(line_of(last)) + 1), "end of file"
    else:
        location, got = Location(path, token.line or 0, token.column or 0), f"'{token}'"
    return ProtocolSyntaxError(location, got, _describe(error.expected), line_of(location.line))


def _describe(terminals: Any) -> list[str]:
    words = set()
    for name in terminals:
        if name in _WORDS:
            words.add(_WORDS[name])
        elif name.startswith("__ANON") or not name.isupper():
            continue
        else:
            words.add(f"'{name.lower()}'")
    return sorted(words)


class _Reader:
    """One walk over a parse tree of either grammar."""

    def __init__(self, path: str, lines: tuple[str, ...], language: str) -> None:
        self.path = path
        self.lines = lines
        self.language = language
        self.refinement_types = False  # the pragma RefinementTypes was given
        self.annotated = False  # a message carries an annotation @"..."

    # ---- helpers ----
    def _loc(self, item: lark.Token | lark.Tree[Any]) -> Location:
        token = item if isinstance(item, lark.Token) else _first_token(item)
        return Location(self.path, token.line or 0, token.column or 0)

    def _name(self, token: lark.Token | lark.Tree[Any]) -> Name:
        assert isinstance(token, lark.Token), token
        return Name(str(token), self._loc(token))

    def _refuse(self, item: lark.Token | lark.Tree[Any], construct: str, reason: str = "") -> NoReturn:
        location = self._loc(item)
        line = self.lines[location.line - 1] if 0 < location.line <= len(self.lines) else ""
        raise UnsupportedConstructError(location, construct, reason, line)

    def _qname(self, node: lark.Tree[Any]) -> Name:
        parts = [str(c) for c in node.children if isinstance(c, lark.Token)]
        return Name(".".join(parts), self._loc(node))

    # ---- module ----
    def module(self, root: lark.Tree[Any]) -> t.ForeignModule:
        aliases: list[t.TypeAlias] = []
        protocols: list[t.Protocol] = []
        for item in root.children:
            if isinstance(item, lark.Token):  # nuScr's pragmas, first in the file
                self._pragmas(item)
                continue
            kind = item.data
            if kind == "type_decl":
                strings = [c for c in item.children if isinstance(c, lark.Token) and c.type == "STRING"]
                name = item.children[-1]
                aliases.append(t.TypeAlias(self._name(name), str(strings[0])[1:-1], self._loc(item)))
            elif kind == "sig_decl":
                self._refuse(item, "a message signature declaration ('sig')",
                             "a message is a label and a payload written at its use")
            elif kind == "protocol":
                protocols.append(self._protocol(item))
            elif kind == "nested":
                self._refuse(item, "a nested protocol ('nested protocol')")
            # module and import declarations name where a file sits; nothing to translate
        imports = any(isinstance(item, lark.Tree) and item.data == "import_decl" for item in root.children)
        return t.ForeignModule(self.language, tuple(aliases), tuple(protocols),
                               declares_types=self.language == "scribble", imports=imports,
                               refinements=self.refinement_types or self.annotated)

    def _pragmas(self, token: lark.Token) -> None:
        """``(*# RefinementTypes, ... #*)``: each name known to nuScr, ``RefinementTypes`` remembered."""
        text, start = str(token), self._loc(token)
        offset = 3
        for part in text[3:-3].split(","):
            name = part.split(":", 1)[0].strip()
            at = location_in(start, text, offset + len(part) - len(part.lstrip()))
            offset += len(part) + 1
            if name not in _PRAGMAS:
                line = self.lines[at.line - 1] if 0 < at.line <= len(self.lines) else ""
                raise ProtocolCheckError([Diagnostic(
                    "error", at, f"unknown pragma {name!r}; expected one of nuScr's: {', '.join(sorted(_PRAGMAS))}",
                    line)])
            if name == "RefinementTypes":
                self.refinement_types = True

    def _expression(self, token: lark.Token, what: str) -> Expr:
        """The nuScr expression inside ``token`` (a refinement's braces, an annotation's quotes)."""
        start = location_in(self._loc(token), str(token), 1)
        try:
            return read_expression(str(token)[1:-1], start, self.lines)
        except ProtocolSyntaxError as error:
            if what == "refinement":
                raise
            self._refuse(token, "an annotation that is not a refinement predicate ('@\"...\"')",
                         f"{error.message}; it is read as nuScr's refinement expressions")

    def _protocol(self, node: lark.Tree[Any]) -> t.Protocol:
        aux = False
        name: lark.Token | None = None
        roles: tuple[Name, ...] = ()
        body: tuple[t.Interaction, ...] = ()
        end = self._loc(node)
        for child in node.children:
            if isinstance(child, lark.Token):
                if child.type == "AUX":
                    aux = True
                elif child.type == "NAME":
                    name = child
                continue
            kind = child.data
            if kind == "modifier":
                token = child.children[0]
                if isinstance(token, lark.Token) and token.type == "EXPLICIT":
                    self._refuse(token, "an explicit protocol ('explicit')",
                                 "connections are implicit: every pair of roles that talks has a channel")
                aux = True
            elif kind == "params":
                self._refuse(child, "a protocol with type or signature parameters ('<...>')")
            elif kind == "roles":
                roles = self._roles(child)
            elif kind == "annotation":
                self._refuse(child, "an annotation ('@\"...\"')")
            elif kind in ("block", "body"):
                body = self._block(child)
                end = self._loc(child.children[-1])
        assert name is not None
        return t.Protocol(self._name(name), roles, body, aux, end, self._loc(node))

    def _roles(self, node: lark.Tree[Any]) -> tuple[Name, ...]:
        names = []
        for child in node.children:
            if isinstance(child, lark.Tree) and child.data == "new_roles":
                self._refuse(child, "roles created by a nested protocol ('new role')")
            if isinstance(child, lark.Tree) and child.data == "role":
                names.append(self._name(child.children[1]))
        return tuple(names)

    # ---- interactions ----
    def _block(self, node: lark.Tree[Any]) -> tuple[t.Interaction, ...]:
        return tuple(self._interaction(c) for c in node.children if isinstance(c, lark.Tree))

    def _interaction(self, node: lark.Tree[Any]) -> t.Interaction:
        handler: Callable[[lark.Tree[Any]], t.Interaction] | None = getattr(
            self, f"_i_{node.data}", None)
        if handler is None:
            self._refuse(node, *_UNSUPPORTED[str(node.data)])
        return handler(node)

    def _i_transfer(self, node: lark.Tree[Any]) -> t.Interaction:
        message, *rest = node.children
        names = [c for c in rest if isinstance(c, lark.Token) and c.type == "NAME"]
        annotation: Expr | None = None
        for child in rest:
            if isinstance(child, lark.Tree) and child.data == "annotation":
                if self.language != "nuscr":
                    self._refuse(child, "an annotation ('@\"...\"')")
                string = child.children[1]
                assert isinstance(string, lark.Token), string
                annotation = self._expression(string, "annotation")
                self.annotated = True
        label, payloads, parens = self._message(message)
        return t.Transfer(label, payloads, parens, self._name(names[0]),
                          tuple(self._name(n) for n in names[1:]), self._loc(node), annotation)

    def _message(self, node: lark.Tree[Any]) -> tuple[Name | None, tuple[t.Payload, ...], bool]:
        if node.data == "bare_message":
            if self.language == "scribble":
                self._refuse(node, "a message signature name",
                             "Scribble declares it with 'sig'; write 'label(Payload)'")
            return self._name(node.children[0]), (), False
        label: Name | None = None
        payloads = []
        for child in node.children:
            if isinstance(child, lark.Token):
                if child.type == "NAME":
                    label = self._name(child)
            elif child.data == "delegation":
                self._refuse(child, "delegation ('Protocol@Role' payload)")
            elif child.data == "refinement":
                payloads.append(self._refined(child))
            else:  # payload: [NAME ':'] qname; a name becomes a field's name if there are several
                named = [c for c in child.children[:-1] if isinstance(c, lark.Token) and c.type == "NAME"]
                payloads.append(t.Payload(self._qname(child.children[-1]),
                                          self._name(named[0]) if named else None))
        return label, tuple(payloads), True

    def _refined(self, node: lark.Tree[Any]) -> t.Payload:
        """``x: T{...}``: a refinement, which nuScr reads only under its pragma ``RefinementTypes``."""
        name, _colon, sort, braces = node.children
        assert isinstance(braces, lark.Token), braces
        if not self.refinement_types:
            location = self._loc(node)
            line = self.lines[location.line - 1] if 0 < location.line <= len(self.lines) else ""
            raise ProtocolCheckError([Diagnostic(
                "error", location, "a refinement type ('x: T{...}') needs the pragma (*# RefinementTypes #*) "
                "first in the file, as nuScr asks", line)])
        return t.Payload(self._name(sort), self._name(name), self._expression(braces, "refinement"))

    def _i_choice(self, node: lark.Tree[Any]) -> t.Interaction:
        role = next(c for c in node.children if isinstance(c, lark.Token) and c.type == "NAME")
        blocks = tuple(self._block(c) for c in node.children if isinstance(c, lark.Tree))
        return t.Choice(self._name(role), blocks, self._loc(node))

    def _i_rec(self, node: lark.Tree[Any]) -> t.Interaction:
        for child in node.children:
            if isinstance(child, lark.Token) and child.type == "STATE":
                self._refuse(child, "recursion with state variables ('rec X [...]')")
        block = node.children[-1]
        return t.Rec(self._name(node.children[1]), self._block(block), self._loc(node))

    def _i_continue(self, node: lark.Tree[Any]) -> t.Interaction:
        for child in node.children:
            if isinstance(child, lark.Token) and child.type == "STATE":
                self._refuse(child, "continue with state expressions ('continue X [...]')")
        return t.Continue(self._name(node.children[1]), self._loc(node))

    def _i_do(self, node: lark.Tree[Any]) -> t.Interaction:
        protocol: Name | None = None
        roles: tuple[Name, ...] = ()
        for child in node.children[1:]:
            if isinstance(child, lark.Token):
                if child.type == "NAME":
                    protocol = self._name(child)
                continue
            if child.data == "qname":
                protocol = self._qname(child)
            elif child.data == "args":
                self._refuse(child, "'do' with type or signature arguments ('<...>')")
            elif child.data == "roles_args":
                roles = tuple(self._name(c) for c in child.children if isinstance(c, lark.Token))
            elif child.data == "annotation":
                self._refuse(child, "an annotation ('@\"...\"')")
        assert protocol is not None
        return t.Do(protocol, roles, self._loc(node))

    def _i_par(self, node: lark.Tree[Any]) -> t.Interaction:
        blocks = tuple(self._block(c) for c in node.children if isinstance(c, lark.Tree))
        return t.Par(blocks, self._loc(node))


_UNSUPPORTED: dict[str, tuple[str, str]] = {
    "connect": ("an explicit connection ('connect')",
                "connections are implicit: every pair of roles that talks has a channel"),
    "disconnect": ("an explicit disconnection ('disconnect')",
                   "a channel lasts as long as the protocol"),
    "wrap": ("a connection wrap ('wrap')", ""),
    "calls": ("a nested protocol call ('calls')", "it creates roles at run time"),
    "nested": ("a nested protocol ('nested protocol')", ""),
}


def _first_token(node: lark.Tree[Any]) -> lark.Token:
    for child in node.children:
        if isinstance(child, lark.Token):
            return child
        if isinstance(child, lark.Tree):
            found = _first_token_or_none(child)
            if found is not None:
                return found
    raise AssertionError(f"a {node.data} without tokens")


def _first_token_or_none(node: lark.Tree[Any]) -> lark.Token | None:
    try:
        return _first_token(node)
    except AssertionError:
        return None
