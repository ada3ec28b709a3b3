"""Text to surface syntax. The only module that imports lark.

:func:`parse_file` returns a :class:`~sessiontypes.syntax.SourceFile` whose
nodes carry locations; bad text raises :class:`ProtocolSyntaxError` with the
line, a caret, and what was expected in words (never lark's token names).
"""

from __future__ import annotations

import bisect
import math
import re
import threading
from collections.abc import Iterator
from fractions import Fraction
from importlib import resources
from typing import Any, cast

import lark
from lark import Token, Transformer
from lark.lexer import Lexer

from . import constraints as c
from . import syntax as s
from .deep import run_deep
from .errors import ProtocolSyntaxError, shortened
from .location import Location

__all__ = ["parse_file", "parse_expression"]

# What each terminal is called in an error message.
TERMINAL_WORDS: dict[str, str] = {
    "NAME": "a name", "STRING": 'a string such as "module:Class"',
    "TYPE": "'type'", "GLOBAL": "'global'", "LOCAL": "'local'", "AT": "'at'",
    "MU": "'mu'", "REC": "'rec'", "MU_SYMBOL": "'μ'", "END": "'end'", "BOTTOM": "'⊥'",
    "ARROW": "'->'", "PLUS": "'+'", "OPLUS": "'⊕'", "AMP": "'&'", "BANG": "'!'",
    "QUERY": "'?'", "PAR": "'||'", "LPAR": "'('", "RPAR": "')'", "LBRACE": "'{'",
    "RBRACE": "'}'", "COMMA": "','", "COLON": "':'", "DOT": "'.'", "EQ": "'='",
    "SEMI": "';'", "$END": "end of file",
    "WITHIN": "'within'", "EVERY": "'every'", "ELSE": "'else'", "TIMEOUT": "'timeout'",
    "AND": "'and'", "OR": "'or'", "NOT": "'not'", "TRUE": "'true'", "FALSE": "'false'",
    "PLUSMINUS": "'+-'", "EQEQ": "'=='", "NE": "'!='", "LE": "'<='", "GE": "'>='", "LT": "'<'",
    "GT": "'>'", "MINUS": "'-'", "STAR": "'*'", "SLASH": "'/'", "PERCENT": "'%'",
    "DURATION": "a duration such as 100ms", "NUMBER": "a number",
}
# Alternative spellings of one token: name only the ASCII one in "expected".
_SYNONYMS = {"REC": "MU", "MU_SYMBOL": "MU", "BOTTOM": "END", "OPLUS": "PLUS"}


_KEYWORDS = {"TYPE", "GLOBAL", "LOCAL", "AT", "MU", "REC", "END"}


def _location(path: str, token: Token) -> Location:
    return Location(path, token.line or 0, token.column or 0)


def _tokens(children: list[Any], kind: str) -> list[Token]:
    return [c for c in children if isinstance(c, Token) and c.type == kind]


def _nodes(children: list[Any]) -> list[Any]:
    return [c for c in children if not isinstance(c, Token)]


class _Builder(Transformer[Token, Any]):
    """Turns lark's parse events into :mod:`sessiontypes.syntax` nodes."""

    def __init__(self) -> None:
        super().__init__()
        self.path = "<string>"
        self.lines: tuple[str, ...] = ()

    def line(self, number: int) -> str:
        return self.lines[number - 1] if 0 < number <= len(self.lines) else ""

    def _name(self, token: Token) -> s.Name:
        return s.Name(str(token), _location(self.path, token))

    def _loc(self, children: list[Any]) -> Location:
        first = children[0]
        if isinstance(first, Token):
            return _location(self.path, first)
        if isinstance(first, s.Name):
            return first.location
        return first.location  # type: ignore[no-any-return]

    # keywords with several spellings: keep the token for its location
    def mu(self, children: list[Any]) -> Token:
        return children[0]  # type: ignore[no-any-return]

    end = plus = mu

    # ---- messages ----
    def msg_paren(self, children: list[Any]) -> s.MessageSyntax:
        names = _tokens(children, "NAME")
        sort = self._name(names[1]) if len(names) > 1 else None
        refinement = _nodes(children)
        return s.MessageSyntax(self._name(names[0]), sort, parens=True,
                               refinement=refinement[0] if refinement else None)

    def msg_fields(self, children: list[Any]) -> s.MessageSyntax:
        return s.MessageSyntax(self._name(children[0]), None, parens=True, fields=tuple(_nodes(children)))

    def field(self, children: list[Any]) -> s.FieldSyntax:
        return s.FieldSyntax(self._name(children[0]), self._name(children[2]),
                             children[3] if len(children) > 3 else None)

    def msg_bare(self, children: list[Any]) -> s.MessageSyntax:
        return s.MessageSyntax(self._name(children[0]), None, parens=False,
                               refinement=children[1] if len(children) > 1 else None)

    # ---- time clauses ----
    def within(self, children: list[Any]) -> list[tuple[str, int, Location]]:
        return [("within", self._duration(children[1]), _location(self.path, children[0]))]

    def every(self, children: list[Any]) -> list[tuple[str, int, Location]]:
        parts = [("every", self._duration(children[1]), _location(self.path, children[0]))]
        if len(children) > 2:
            parts.append(("jitter", self._duration(children[3]), _location(self.path, children[2])))
        return parts

    def on_expiry(self, children: list[Any]) -> list[tuple[str, int, Location]]:
        return [("else", 0, _location(self.path, children[0]))]

    def timing(self, children: list[Any]) -> s.TimingSyntax:
        values: dict[str, int] = {}
        parts: list[tuple[str, Location]] = []
        for part in children:
            for name, value, location in part:
                if name in values:
                    word = "else timeout" if name == "else" else name
                    raise ProtocolSyntaxError(location, f"'{word}' again",
                                              ["each of 'every', 'within' and 'else timeout' at most once"],
                                              self.line(location.line), "a time clause says each part once")
                values[name] = value
                parts.append((name, location))
        timing = c.Timing(values.get("within"), values.get("every"), values.get("jitter", 0), "else" in values,
                          parts[0][1])
        return s.TimingSyntax(timing, tuple(parts))

    def _duration(self, token: Token) -> int:
        """A duration's whole nanoseconds; one that is not whole is an error."""
        match = re.fullmatch(r"([0-9.]+)(.*)", str(token))
        assert match is not None
        unit = "us" if match[2] in ("µs", "μs") else match[2]
        nanos = Fraction(match[1]) * c.NANOS[unit]
        if nanos.denominator != 1:
            location = _location(self.path, token)
            raise ProtocolSyntaxError(location, f"'{token}'", ["a whole number of nanoseconds"],
                                      self.line(location.line),
                                      "durations are whole nanoseconds")
        return int(nanos)

    # ---- refinements ----
    def refinement(self, children: list[Any]) -> c.Expr:
        return children[1]  # type: ignore[no-any-return]

    def expression_only(self, children: list[Any]) -> c.Expr:
        return children[0]  # type: ignore[no-any-return]

    def _fold(self, children: list[Any]) -> c.Expr:
        """``a op b op c`` as ``(a op b) op c``: left-associative, as in Python."""
        left: c.Expr = children[0]
        for index in range(1, len(children), 2):
            left = c.Binary(str(children[index]), left, children[index + 1], _expr_location(children[0]))
        return left

    or_expr = and_expr = sum = product = _fold

    def negation(self, children: list[Any]) -> c.Expr:
        return c.Unary("not", children[1], _location(self.path, children[0]))

    def minus(self, children: list[Any]) -> c.Expr:
        return c.Unary("-", children[1], _location(self.path, children[0]))

    def comparison(self, children: list[Any]) -> c.Expr:
        return c.Compare(tuple([str(op) for op in children[1::2]]), tuple(children[0::2]),
                         _expr_location(children[0]))

    def number(self, children: list[Any]) -> c.Expr:
        text = str(children[0])
        value: int | float = int(text) if text.isdigit() else float(text)
        location = _location(self.path, children[0])
        if math.isinf(value):
            raise ProtocolSyntaxError(location, f"'{shortened(text)}'", ["a number a float can hold"],
                                      self.line(location.line), "it is too large to compare with")
        return c.Number(value, location)

    def text(self, children: list[Any]) -> c.Expr:
        return c.Text(_unescape(str(children[0])[1:-1]), _location(self.path, children[0]))

    def truth(self, children: list[Any]) -> c.Expr:
        return c.Truth(children[0].type == "TRUE", _location(self.path, children[0]))

    def call(self, children: list[Any]) -> c.Expr:
        name = children[0]
        location = _location(self.path, name)
        args = tuple(_nodes(children))
        arity = {"abs": "one argument", "len": "one argument", "min": "two or more arguments",
                 "max": "two or more arguments"}
        if str(name) not in c.FUNCTIONS:
            raise ProtocolSyntaxError(location, f"'{name}('", ["one of the functions abs, min, max, len"],
                                      self.line(location.line), "a refinement calls only these functions")
        if (len(args) == 1) != (str(name) in ("abs", "len")):
            raise ProtocolSyntaxError(location, f"{name} of {len(args)} argument{'s' * (len(args) != 1)}",
                                      [f"{name} of {arity[str(name)]}"], self.line(location.line), "")
        return c.Call(str(name), args, location)

    def name_path(self, children: list[Any]) -> c.Expr:
        return c.Path(tuple([str(n) for n in _tokens(children, "NAME")]), _location(self.path, children[0]))

    def parenthesised(self, children: list[Any]) -> c.Expr:
        return children[1]  # type: ignore[no-any-return]

    # ---- global ----
    def ginteraction(self, children: list[Any]) -> s.GInteraction:
        # NAME ARROW NAME COLON msg [timing] [DOT gtype]: the hottest rule, indexed directly
        timing = None
        if len(children) > 5 and isinstance(children[-1], s.TimingSyntax):
            timing = children.pop()
        elif len(children) > 6 and isinstance(children[-3], s.TimingSyntax):
            timing = children.pop(-3)
        if children[3].type != "COLON":  # a multicast: NAME ARROW NAME (COMMA NAME)+ COLON ...
            colon = next(i for i, c in enumerate(children) if isinstance(c, Token) and c.type == "COLON")
            receivers = self._receivers(children[2:colon])
            rest = children[colon + 3] if len(children) > colon + 3 else None
            return self._multicast(self._name(children[0]), receivers,
                                   (s.GBranchSyntax(children[colon + 1], rest),), braced=False, timing=timing)
        sender, receiver = self._name(children[0]), self._name(children[2])
        branch = s.GBranchSyntax(children[4], children[6] if len(children) > 6 else None)
        return s.GInteraction(sender, receiver, (branch,), False, sender.location, timing)

    def gchoice(self, children: list[Any]) -> s.GInteraction:
        colon = next(i for i, c in enumerate(children) if isinstance(c, Token) and c.type == "COLON")
        nodes = _nodes(children)
        timing = nodes.pop() if isinstance(nodes[-1], s.TimingSyntax) else None
        return self._multicast(self._name(children[0]), self._receivers(children[2:colon]),
                               tuple(nodes), braced=True, timing=timing)

    def _receivers(self, tokens: list[Any]) -> list[s.Name]:
        """The receivers of ``A -> B, C``, each once (a repeated one is an error)."""
        receivers: list[s.Name] = []
        for token in _tokens(tokens, "NAME"):
            name = self._name(token)
            if any(r.text == name.text for r in receivers):
                raise ProtocolSyntaxError(name.location, f"'{name.text}' again", ["a receiver not listed yet"],
                                          self.line(name.location.line),
                                          "a multicast sends to each receiver once")
            receivers.append(name)
        return receivers

    def _multicast(self, sender: s.Name, receivers: list[s.Name], branches: tuple[s.GBranchSyntax, ...],
                   braced: bool, timing: s.TimingSyntax | None = None) -> s.GInteraction:
        """``p -> q1, ..., qn : {l_i. G_i}`` as ``p -> q1 : {l_i. p -> q2 : l_i. ... p -> qn : l_i. G_i}``.

        The message of each branch goes to the receivers in written order; every
        interaction of the expansion is located at the multicast's sender, and carries
        the multicast's time clause (each send is one interaction of its own).
        """
        first, *others = receivers
        expanded: list[s.GBranchSyntax] = []
        for branch in branches:
            rest = branch.continuation
            for receiver in reversed(others):
                rest = s.GInteraction(sender, receiver, (s.GBranchSyntax(branch.message, rest),), False,
                                      sender.location, timing)
            expanded.append(s.GBranchSyntax(branch.message, rest))
        return s.GInteraction(sender, first, tuple(expanded), braced, sender.location, timing)

    def grouted(self, children: list[Any]) -> s.GRouted:
        sender = self._name(children[0])
        branches = tuple([s.GInteraction(sender, receiver, (branch,), False, receiver.location)
                          for receiver, branch in _nodes(children)])
        return s.GRouted(sender, branches, sender.location)

    def groute(self, children: list[Any]) -> tuple[s.Name, s.GBranchSyntax]:
        nodes = _nodes(children)
        return self._name(children[0]), s.GBranchSyntax(nodes[0], nodes[1] if len(nodes) > 1 else None)

    def gbranch_msg(self, children: list[Any]) -> s.GBranchSyntax:
        nodes = _nodes(children)
        return s.GBranchSyntax(nodes[0], nodes[1] if len(nodes) > 1 else None)

    def gbranch_label(self, children: list[Any]) -> s.GBranchSyntax:
        label = self._name(children[0])
        return s.GBranchSyntax(s.MessageSyntax(label, None, parens=True), children[2])

    def grec(self, children: list[Any]) -> s.GRec:
        return s.GRec(self._name(children[1]), children[3], _location(self.path, children[0]))

    def gref(self, children: list[Any]) -> s.GRef:
        return s.GRef(self._name(children[0]))

    def gend(self, children: list[Any]) -> s.GEnd:
        return s.GEnd(_location(self.path, children[0]))

    def gparen(self, children: list[Any]) -> Any:
        return children[1]

    def gpar(self, children: list[Any]) -> s.GParallel:
        return s.GParallel(tuple(_nodes(children)), _location(self.path, children[0]))

    # ---- local ----
    def _action(self, children: list[Any], direction: str, binary: bool) -> s.LAction:
        names = _tokens(children, "NAME")
        nodes = _nodes(children)
        timing = next((n for n in nodes if isinstance(n, s.TimingSyntax)), None)
        nodes = [n for n in nodes if not isinstance(n, s.TimingSyntax)]
        if binary:
            peer = None
            message = s.MessageSyntax(self._name(names[0]), None, parens=False)
            rest = nodes
        else:
            peer = self._name(names[0])
            message, rest = nodes[0], nodes[1:]
        return s.LAction(direction, peer, message, rest[0] if rest else None,  # type: ignore[arg-type]
                         _location(self.path, children[0]), timing)

    def lsend(self, children: list[Any]) -> s.LAction:
        return self._action(children, "!", binary=False)

    def lrecv(self, children: list[Any]) -> s.LAction:
        return self._action(children, "?", binary=False)

    def lsend_binary(self, children: list[Any]) -> s.LAction:
        return self._action(children, "!", binary=True)

    def lrecv_binary(self, children: list[Any]) -> s.LAction:
        return self._action(children, "?", binary=True)

    def _choice(self, children: list[Any], kind: str) -> s.LChoice:
        peers = _tokens(children, "NAME")
        peer = self._name(peers[0]) if peers else None
        nodes = _nodes(children)
        timing = nodes.pop() if isinstance(nodes[-1], s.TimingSyntax) else None
        return s.LChoice(kind, peer, tuple(nodes),  # type: ignore[arg-type]
                         _location(self.path, children[0]), timing)

    def lselect(self, children: list[Any]) -> s.LChoice:
        return self._choice(children, "+")

    def loffer(self, children: list[Any]) -> s.LChoice:
        return self._choice(children, "&")

    def lselect_among(self, children: list[Any]) -> s.LChoiceAmong:
        return s.LChoiceAmong("+", tuple(_nodes(children)), _location(self.path, children[0]))

    def loffer_among(self, children: list[Any]) -> s.LChoiceAmong:
        return s.LChoiceAmong("&", tuple(_nodes(children)), _location(self.path, children[0]))

    lsend_branch = lsend
    lrecv_branch = lrecv

    def lbranch_msg(self, children: list[Any]) -> s.LBranchSyntax:
        nodes = _nodes(children)
        return s.LBranchSyntax(nodes[0], nodes[1] if len(nodes) > 1 else None)

    def lbranch_label(self, children: list[Any]) -> s.LBranchSyntax:
        label = self._name(children[0])
        return s.LBranchSyntax(s.MessageSyntax(label, None, parens=True), children[2])

    def lrec(self, children: list[Any]) -> s.LRec:
        return s.LRec(self._name(children[1]), children[3], _location(self.path, children[0]))

    def lref(self, children: list[Any]) -> s.LRef:
        return s.LRef(self._name(children[0]))

    def lend(self, children: list[Any]) -> s.LEnd:
        return s.LEnd(_location(self.path, children[0]))

    lparen = gparen

    def lpar(self, children: list[Any]) -> s.LParallel:
        return s.LParallel(tuple(_nodes(children)), _location(self.path, children[0]))

    # ---- declarations ----
    def type_decl(self, children: list[Any]) -> s.TypeDecl:
        keyword, name, _, string = children
        target = _unescape(str(string)[1:-1])
        return s.TypeDecl(self._name(name), target, _location(self.path, keyword))

    def roles(self, children: list[Any]) -> tuple[s.Name, ...]:
        return tuple(self._name(t) for t in _tokens(children, "NAME"))

    def global_decl(self, children: list[Any]) -> s.GlobalDecl:
        keyword, name = children[0], children[1]
        roles = children[2] if isinstance(children[2], tuple) else None
        return s.GlobalDecl(self._name(name), roles, children[-1], _location(self.path, keyword))

    def local_decl(self, children: list[Any]) -> s.LocalDecl:
        names = _tokens(children, "NAME")
        role = self._name(names[1]) if len(names) > 1 else None
        return s.LocalDecl(self._name(names[0]), role, children[-1],
                           _location(self.path, children[0]))

    def start(self, children: list[Any]) -> tuple[s.Declaration, ...]:
        return tuple(_nodes(children))


# One regular expression for every token; lark's general lexer is several times
# slower and lexing dominated parse time. Names equal to a keyword are keywords.
_TOKEN = re.compile(r"""
    (?:[\s\ufeff]+|//[^\n]*|/\*(?:[^*]|\*(?!/))*\*/)*    # skipped: white space (WS), comments
    (?:
      (?P<NAME>[A-Za-z_][A-Za-z0-9_]*'*)
    | (?P<DURATION>[0-9]+(?:\.[0-9]+)?(?:ns|us|µs|μs|ms|s)(?![A-Za-z0-9_']))
    | (?P<NUMBER>[0-9]+(?:\.[0-9]+)?(?:[eE][+-]?[0-9]+)?)
    | (?P<STRING>"(?:[^"\\\n]|\\.)*")
    | (?P<ARROW>->|→)
    | (?P<PAR>\|\|)
    | (?P<OPERATOR>\+-|==|!=|<=|>=)
    | (?P<PUNCT>[(){},:.=;!?&+⊕μ⊥±<>*/%-])
    | (?P<BAD>.)
    | \Z                                           # trailing skipped text
    )
""", re.VERBOSE | re.DOTALL)
_PUNCTUATION = {
    "(": "LPAR", ")": "RPAR", "{": "LBRACE", "}": "RBRACE", ",": "COMMA", ":": "COLON",
    ".": "DOT", "=": "EQ", ";": "SEMI", "!": "BANG", "?": "QUERY", "&": "AMP", "+": "PLUS",
    "⊕": "OPLUS", "μ": "MU_SYMBOL", "⊥": "BOTTOM", "±": "PLUSMINUS", "<": "LT", ">": "GT",
    "*": "STAR", "/": "SLASH", "%": "PERCENT", "-": "MINUS",
    "+-": "PLUSMINUS", "==": "EQEQ", "!=": "NE", "<=": "LE", ">=": "GE",
}
_KEYWORD_TYPES = {"type": "TYPE", "global": "GLOBAL", "local": "LOCAL", "at": "AT",
                  "mu": "MU", "rec": "REC", "end": "END"}
# Keywords only where the parser can take one (time clauses, refinements): a protocol that
# names a role or a label ``timeout`` or ``every`` means the name everywhere else.
_CONTEXTUAL_TYPES = {"within": "WITHIN", "every": "EVERY", "else": "ELSE", "timeout": "TIMEOUT",
                     "and": "AND", "or": "OR", "not": "NOT", "true": "TRUE", "false": "FALSE"}


class _FastLexer(Lexer):
    """Tokens for the grammar's terminals; an unknown character becomes a BAD
    token, which the parser rejects with the set of tokens it expected there.

    It is told the parser's state (lark's interface 1), for the contextual keywords."""

    __future_interface__ = 1

    def __init__(self, lexer_conf: Any) -> None:
        pass

    def lex(self, lexer_state: Any, parser_state: Any) -> Iterator[Token]:
        data = lexer_state.text
        if not isinstance(data, str):  # lark's TextSlice of the whole text
            data = data.text
        states = parser_state.parse_conf.states
        newlines = [i for i, char in enumerate(data) if char == "\n"]
        for match in _TOKEN.finditer(data):
            kind = match.lastgroup
            if kind is None:  # only skipped text was left
                continue
            start = match.start(kind)
            value = match.group(kind)
            if kind == "NAME":
                kind = _KEYWORD_TYPES.get(value, "NAME")
                contextual = _CONTEXTUAL_TYPES.get(value)
                if contextual is not None and contextual in states[parser_state.position]:
                    kind = contextual
            elif kind in ("PUNCT", "OPERATOR"):
                kind = _PUNCTUATION[value]
                if value == "+-" and "PLUSMINUS" not in states[parser_state.position]:
                    # ``a +-b`` in a refinement: plus, then minus
                    yield _token("PLUS", "+", start, newlines)
                    kind, value, start = "MINUS", "-", start + 1
            # inlined _token: lexing dominates parse time
            line = bisect.bisect_left(newlines, start)
            line_start = newlines[line - 1] + 1 if line else 0
            token = str.__new__(Token, value)
            token.type, token.value, token.start_pos = kind, value, start
            token.line, token.column = line + 1, start - line_start + 1
            token.end_line = token.end_column = token.end_pos = None
            yield token


def _token(kind: str, value: str, start: int, newlines: list[int]) -> Token:
    line = bisect.bisect_left(newlines, start)
    line_start = newlines[line - 1] + 1 if line else 0
    # Token(...) goes through a slow keyword-argument constructor; fill the slots.
    token = str.__new__(Token, value)
    token.type, token.value, token.start_pos = kind, value, start
    token.line, token.column = line + 1, start - line_start + 1
    token.end_line = token.end_column = token.end_pos = None
    return token


_builder = _Builder()
_built: list[lark.Lark] = []  # the parser, once a parse needed it


def _parser() -> lark.Lark:
    """The grammar's LALR parser, built at the first parse (under ``_lock``): building it takes a
    sixth of a second, which every process importing anodize paid, its group processes too, though
    most never parse a protocol."""
    if not _built:
        _built.append(lark.Lark(
            resources.files(__package__).joinpath("grammar.lark").read_text(encoding="utf-8"),
            parser="lalr",
            lexer=_FastLexer,
            start=["start", "expression_only"],
            transformer=_builder,
            maybe_placeholders=False,
        ))
    return _built[0]


# The builder knows the current file's path; one parse at a time uses it.
_lock = threading.Lock()


def parse_file(text: str, path: str = "<string>") -> s.SourceFile:
    """Parse protocol ``text`` (read from ``path``) into surface syntax.

    Raises:
        ProtocolSyntaxError: the text does not follow the grammar.
    """
    return run_deep(_parse, text, path)


def parse_expression(text: str, path: str = "<string>") -> c.Expr:
    """Parse ``text`` as one refinement predicate (the language inside ``{...}``).

    Raises:
        ProtocolSyntaxError: the text is not one expression.
    """
    lines = _lines(text)
    with _lock:
        _builder.path, _builder.lines = path, lines
        try:
            return cast("c.Expr", _parser().parse(text, start="expression_only"))
        except lark.exceptions.UnexpectedInput as error:
            raise _syntax_error(error, text, lines, path) from None


def _expr_location(node: Any) -> Location:
    return node.location  # type: ignore[no-any-return]


def _parse(text: str, path: str) -> s.SourceFile:
    lines = _lines(text)
    with _lock:
        _builder.path, _builder.lines = path, lines
        try:
            # The builder's start() turns the tree into the declarations.
            declarations = cast("tuple[s.Declaration, ...]", _parser().parse(text, start="start"))
        except lark.exceptions.UnexpectedInput as error:
            raise _syntax_error(error, text, lines, path) from None
    return s.SourceFile(path, lines, declarations)


def _lines(text: str) -> tuple[str, ...]:
    """The lines of ``text`` as locations count them: broken at newlines only.

    ``str.splitlines`` also breaks at form feeds, U+2028 and other characters that
    the lexer takes for white space; a line number would then show the wrong line.
    """
    lines = text.split("\n")
    if not lines[-1]:  # the newline that ends the last line starts no new one
        lines.pop()
    return tuple([line.removesuffix("\r") for line in lines])


def _syntax_error(
    error: lark.exceptions.UnexpectedInput, text: str, lines: tuple[str, ...], path: str
) -> ProtocolSyntaxError:
    def line_of(number: int) -> str:
        return lines[number - 1] if 0 < number <= len(lines) else ""

    if isinstance(error, lark.exceptions.UnexpectedCharacters):
        position = error.pos_in_stream or 0
        char = text[position] if position < len(text) else ""
        location = Location(path, error.line, error.column)
        hint = ""
        if text.startswith("/*", position):
            got, hint = "'/*'", "this comment is never closed with '*/'"
        elif char == '"':
            got, hint = "'\"'", "this string is never closed"
        else:
            got = f"character {char!r}"
        expected = _describe(error.allowed or ())
        return ProtocolSyntaxError(location, got, expected, line_of(error.line), hint)

    assert isinstance(error, lark.exceptions.UnexpectedToken), error
    token = error.token
    # LALR's expected set may name tokens this exact spot cannot take; ask the parser.
    try:
        # lark leaves accepts() unannotated
        acceptable = set(error.interactive_parser.accepts()) or set(error.expected)  # type: ignore[no-untyped-call]
    except Exception:  # defensive: fall back to LALR's own set
        acceptable = set(error.expected)
    if token.type == "BAD" or (token.type == "SLASH" and text.startswith("/*", token.start_pos or 0)):
        location = _location(path, token)
        hint = ""
        if text.startswith("/*", token.start_pos or 0):
            got, hint = "'/*'", "this comment is never closed with '*/'"
        elif str(token) == '"':
            got, hint = "'\"'", "this string is never closed on its line"
        else:
            got = f"character {str(token)!r}"
        return ProtocolSyntaxError(location, got, _describe(acceptable), line_of(location.line), hint)
    if token.type == "$END":
        last = len(lines) or 1
        location = Location(path, last, len(line_of(last)) + 1)
        got = "end of file"
    else:
        location = _location(path, token)
        got = f"'{shortened(str(token))}'"
    return ProtocolSyntaxError(location, got, _describe(acceptable), line_of(location.line),
                               _hint(token, acceptable))


def _describe(terminals: Any) -> list[str]:
    names = {_SYNONYMS.get(t, t) for t in terminals}
    return sorted(TERMINAL_WORDS.get(t, t.lower()) for t in names)


def _hint(token: Token, expected: set[str]) -> str:
    """A sentence for mistakes people make often, else ""."""
    if token.type in {"TYPE", "GLOBAL", "LOCAL"} and "MU" in expected:
        return "the declaration before it is incomplete"
    if token.type in _KEYWORDS and "NAME" in expected:
        return f"'{token}' is a keyword and cannot be a name"
    if token.type == "NAME" and expected <= {"TYPE", "GLOBAL", "LOCAL", "SEMI", "$END"}:
        return "interactions are sequenced with '.', and ';' ends a declaration"
    if token.type == "NAME" and "DOT" in expected:
        return "interactions are sequenced with '.'"
    if token.type == "NAME" and "COLON" in expected and "RPAR" in expected:
        return "a named payload is written 'name: Sort'"
    if token.type == "NAME" and "COLON" in expected:
        return "write 'Sender -> Receiver : label'"
    if token.type == "ARROW" and "EQ" in expected:
        return "a declaration starts 'global Name = ...'"
    if token.type == "NUMBER" and "DURATION" in expected:
        return "a duration is a number with its unit right after it: ns, us, ms or s, as in 100ms"
    if token.type in {"BANG", "QUERY", "PLUS", "AMP"} and "NAME" in expected and "LBRACE" not in expected:
        return "'!', '?', '+' and '&' belong in local types"
    return ""


_ESCAPES = {"n": "\n", "t": "\t", "\\": "\\", '"': '"'}


def _unescape(body: str) -> str:
    r"""A string literal's text: ``\\``, ``\"``, ``\n`` and ``\t`` stand for their character, any
    other backslash for itself (no warning, no error: a target is checked later), every other
    character as written (not re-decoded, so non-ASCII text stays intact)."""
    return re.sub(r"\\(.)", lambda m: _ESCAPES.get(m[1], m[0]), body)
