"""refine.py against independent references: evaluation (compile_predicate) and print (print_expr).

Evaluation: each expression is translated to Python source with explicit checks of what each
operator takes (the semantics docs/language.md states, written the other way round), evaluated
with ``eval``, and the outcome (true, false, fails) must be compile_predicate's.

Print: the printed text, with ``true``/``false`` spelled as Python's, is parsed by Python
(whose precedence and associativity the language takes on purpose) and read back into an
expression, which must be the one printed: every parenthesis needed is there.
"""

from __future__ import annotations

import ast
import numbers
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from sessiontypes.constraints import Binary, Call, Compare, Expr, Number, Path, Text, Truth, Unary
from sessiontypes.refine import compile_predicate, print_expr

NAMES = ("a", "b", "c", "e", "z")  # e is an earlier payload's; z is nowhere

# ---- expressions ----------------------------------------------------------------------------

leaves: st.SearchStrategy[Expr] = st.one_of(
    st.integers(0, 10**6).map(Number),
    st.floats(0, 1e6, allow_nan=False, allow_infinity=False).map(Number),
    st.text(st.characters(min_codepoint=32, max_codepoint=0x2FF), max_size=4).map(Text),
    st.booleans().map(Truth),
    st.lists(st.sampled_from((*NAMES, "x", "y")), min_size=1, max_size=3)
    .filter(lambda parts: parts[0] in NAMES).map(lambda parts: Path(tuple(parts))),
)


def _compound(inner: st.SearchStrategy[Expr]) -> st.SearchStrategy[Expr]:
    return st.one_of(
        st.builds(Unary, st.sampled_from(("not", "-")), inner),
        st.builds(Binary, st.sampled_from(("and", "or", "+", "-", "*", "/", "%")), inner, inner),
        st.integers(1, 3).flatmap(lambda n: st.builds(
            Compare, st.lists(st.sampled_from(("==", "!=", "<", "<=", ">", ">=")), min_size=n, max_size=n)
            .map(tuple), st.lists(inner, min_size=n + 1, max_size=n + 1).map(tuple))),
        st.builds(Call, st.sampled_from(("abs", "len")), st.tuples(inner)),
        st.builds(Call, st.sampled_from(("min", "max")), st.lists(inner, min_size=2, max_size=3).map(tuple)),
    )


expressions = st.recursive(leaves, _compound, max_leaves=12)

values = st.recursive(
    st.one_of(st.integers(-5, 5), st.floats(-4, 4), st.sampled_from([0, 0.0, -0.0, float("inf"), float("nan")]),
              st.booleans(), st.text(max_size=3), st.binary(max_size=3), st.none()),
    lambda inner: st.one_of(st.lists(inner, max_size=3),
                            st.fixed_dictionaries({}, optional={"x": inner, "y": inner})),
    max_leaves=4)
payloads = st.fixed_dictionaries({}, optional={"a": values, "b": values, "c": values})
earliers = st.fixed_dictionaries({}, optional={"e": values, "a": values})

# ---- the reference: Python source with explicit checks ---------------------------------------


class _FailsError(Exception):
    pass


def _kind(value: object) -> str:
    if value is True or value is False:
        return "bool"
    if isinstance(value, numbers.Real):
        return "number"
    return {str: "str", bytes: "bytes"}.get(type(value), "other")


def _num(value: object) -> object:
    if _kind(value) != "number":
        raise _FailsError
    return value


def _bool(value: object) -> bool:
    if _kind(value) != "bool":
        raise _FailsError
    return bool(value)


def _sized(value: object) -> Any:
    if _kind(value) in ("number", "bool"):
        raise _FailsError
    return value


def _comparable(op: str, left: object, right: object) -> bool:
    kinds = {_kind(left), _kind(right)}
    if len(kinds) != 1 or (op not in ("==", "!=") and kinds & {"bool", "other"}):
        raise _FailsError
    return True


def _read(parts: tuple[str, ...], payload: dict[str, object], earlier: dict[str, object]) -> object:
    head, *rest = parts
    if head in payload:
        value = payload[head]
    elif head in earlier:
        value = earlier[head]
    else:
        raise _FailsError
    for name in rest:
        if not isinstance(value, dict) or name not in value:
            raise _FailsError
        value = value[name]
    return value


class _Source:
    """An expression as Python source over _num/_bool/_sized/_comparable/_read."""

    def __init__(self) -> None:
        self.temporaries = 0

    def of(self, expr: Expr) -> str:
        match expr:
            case Number() | Text():
                return repr(expr.value)
            case Truth():
                return "True" if expr.value else "False"
            case Path():
                return f"_read({expr.parts!r}, payload, earlier)"
            case Unary(op="not"):
                return f"(not _bool({self.of(expr.operand)}))"
            case Unary():
                return f"(-_num({self.of(expr.operand)}))"
            case Binary(op="and" | "or"):
                return f"(_bool({self.of(expr.left)}) {expr.op} _bool({self.of(expr.right)}))"
            case Binary():
                return f"(_num({self.of(expr.left)}) {expr.op} _num({self.of(expr.right)}))"
            case Compare():
                names = [self._temporary() for _ in expr.operands]
                first = f"({names[0]} := {self.of(expr.operands[0])})"
                tests = [f"_comparable({op!r}, {first if i == 0 else names[i]}, "
                         f"({names[i + 1]} := {self.of(expr.operands[i + 1])})) and bool({names[i]} {op} "
                         f"{names[i + 1]})" for i, op in enumerate(expr.ops)]
                return "(" + " and ".join(f"({t})" for t in tests) + ")"
            case Call(function="len"):
                return f"len(_sized({self.of(expr.args[0])}))"
            case Call():
                return f"{expr.function}({', '.join(f'_num({self.of(a)})' for a in expr.args)})"
        raise AssertionError(expr)

    def _temporary(self) -> str:
        self.temporaries += 1
        return f"t{self.temporaries}"


def reference(expr: Expr, payload: dict[str, object], earlier: dict[str, object]) -> str:
    source = _Source().of(expr)
    scope = {"_num": _num, "_bool": _bool, "_sized": _sized, "_comparable": _comparable, "_read": _read,
             "payload": payload, "earlier": earlier, "len": len, "abs": abs, "min": min, "max": max}
    try:
        value = eval(source, scope)  # our own generated text
    except (_FailsError, ZeroDivisionError, OverflowError, TypeError, ValueError):
        return "fails"
    if value is True or value is False:
        return "true" if value else "false"
    return "fails"


def outcome(expr: Expr, payload: dict[str, object], earlier: dict[str, object]) -> str:
    reason = compile_predicate(expr)(payload, earlier)
    if reason is None:
        return "true"
    return "false" if reason.endswith(" is false") else "fails"


@settings(max_examples=300, deadline=None)
@given(expressions, payloads, earliers)
def test_compile_predicate_agrees_with_the_reference(expr: Expr, payload: dict[str, object],
                                                     earlier: dict[str, object]) -> None:
    assert outcome(expr, payload, earlier) == reference(expr, payload, earlier), print_expr(expr)


def test_a_bool_is_no_number_and_one_kind_is_compared() -> None:
    assert outcome(Compare(("==",), (Binary("+", Truth(True), Number(1)), Number(2))), {}, {}) == "fails"
    assert outcome(Compare(("==",), (Number(1), Truth(True))), {}, {}) == "fails"
    assert outcome(Compare(("<",), (Truth(False), Truth(True))), {}, {}) == "fails"
    assert outcome(Compare((">",), (Call("abs", (Truth(True),)), Number(0))), {}, {}) == "fails"
    assert outcome(Compare((">",), (Call("len", (Number(3),)), Number(0))), {}, {}) == "fails"
    assert outcome(Compare(("==",), (Binary("+", Text("a"), Text("b")), Text("ab"))), {}, {}) == "fails"
    assert outcome(Compare(("<",), (Path(("a",)), Number(2))), {"a": 1.5}, {}) == "true"


def test_a_failure_says_why() -> None:
    check = compile_predicate(Compare((">",), (Binary("+", Path(("flag",)), Number(1)), Number(0))))
    assert check({"flag": True}, {}) == ("refinement {flag + 1 > 0} cannot be evaluated: + takes numbers, "
                                         "not bool True")


# ---- print: Python reads the printed text back to the same expression ------------------------

def _from_python(node: ast.expr) -> Expr:
    match node:
        case ast.Constant(value=bool() as value):
            return Truth(value)
        case ast.Constant(value=int() | float() as value):
            return Number(value)
        case ast.Constant(value=str() as value):
            return Text(value)
        case ast.Name():
            return Path((node.id,))
        case ast.Attribute():
            inner = _from_python(node.value)
            assert isinstance(inner, Path)
            return Path((*inner.parts, node.attr))
        case ast.UnaryOp(op=ast.Not()):
            return Unary("not", _from_python(node.operand))
        case ast.UnaryOp(op=ast.USub()):
            return Unary("-", _from_python(node.operand))
        case ast.BoolOp():
            op = "and" if isinstance(node.op, ast.And) else "or"
            result = _from_python(node.values[0])
            for value in node.values[1:]:
                result = Binary(op, result, _from_python(value))
            return result
        case ast.BinOp():
            op = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Mod: "%"}[type(node.op)]
            return Binary(op, _from_python(node.left), _from_python(node.right))
        case ast.Compare():
            ops = tuple({ast.Eq: "==", ast.NotEq: "!=", ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">",
                         ast.GtE: ">="}[type(o)] for o in node.ops)
            return Compare(ops, tuple(_from_python(o) for o in (node.left, *node.comparators)))
        case ast.Call(func=ast.Name()):
            return Call(node.func.id, tuple(_from_python(a) for a in node.args))
    raise AssertionError(ast.dump(node))


def _as_python(text: str) -> str:
    """Our text as Python's: only the spelling of true and false differs (outside strings)."""
    return "".join([{"true": "True", "false": "False"}.get(word, word) for word in _words(text)])


def _words(text: str) -> list[str]:
    """``text`` split into string literals, identifiers and the rest (joined back unchanged)."""
    parts: list[str] = []
    index = 0
    while index < len(text):
        char = text[index]
        if char == '"':
            end = index + 1
            while text[end] != '"':
                end += 2 if text[end] == "\\" else 1
            parts.append(text[index:end + 1])
            index = end + 1
        elif char.isalpha() or char == "_":
            end = index
            while end < len(text) and (text[end].isalnum() or text[end] == "_"):
                end += 1
            parts.append(text[index:end])
            index = end
        else:
            parts.append(char)
            index += 1
    return parts


@settings(max_examples=300, deadline=None)
@given(expressions)
def test_print_expr_reads_back_through_pythons_precedence(expr: Expr) -> None:
    text = print_expr(expr)
    assert _from_python(ast.parse(_as_python(text), mode="eval").body) == expr, text


def test_print_expr_parenthesises_only_where_needed() -> None:
    x, y, z = Path(("x",)), Path(("y",)), Path(("z",))
    assert print_expr(Binary("-", x, Binary("-", y, z))) == "x - (y - z)"
    assert print_expr(Binary("-", Binary("-", x, y), z)) == "x - y - z"
    assert print_expr(Unary("not", Compare(("==",), (x, y)))) == "not x == y"
    assert print_expr(Compare(("<",), (Compare(("<",), (x, y)), z))) == "(x < y) < z"
    assert print_expr(Binary("*", Unary("-", x), Binary("+", y, Number(1.5)))) == "-x * (y + 1.5)"
