"""The check of a ROS 2 message against its definition, compiled once per type.

A check runs on every message a monitor sees, so each type gets two functions: a
generated one for the common case (exactly the class, every field of its commonest
shape: one boolean expression, no call per field), and a field-by-field one that
accepts what is rarer (a subclass, numpy scalars, lists for arrays) and says why
anything else does not fit, naming the field's path (``header.stamp.sec``,
``poses[3].pose``). A third turns a fitting value into what rosbags' serialiser
takes (lists of numbers into numpy arrays), copying only what it changes.

Field definitions are rosbags' (``Typestore.fielddefs[name][1]``); nothing here imports
rosbags, and numpy only when a type is compiled.
"""

from __future__ import annotations

import copy
import keyword
import math
import reprlib
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

__all__ = ["Compiled", "Failure", "compile_message", "failure_text", "attr_name"]

# Where below a value a check failed (".header.stamp.sec", "[3]", "" for the value itself),
# what was expected there, and what was found; the text is built only for a failure.
Failure = tuple[str, str, str]
_Explain = Callable[[object], "Failure | None"]
_Prepare = Callable[[Any], Any]

# rosbags' field descriptions: (Nodetype, detail); see rosbags.interfaces.Nodetype.
_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4

# Integer kinds as rosbags packs them (a byte is a signed char to rosbags' struct codes).
_INTEGERS: dict[str, tuple[int, int, str]] = {
    "int8": (-2**7, 2**7 - 1, "-128..127"), "uint8": (0, 2**8 - 1, "0..255"),
    "int16": (-2**15, 2**15 - 1, "-32768..32767"), "uint16": (0, 2**16 - 1, "0..65535"),
    "int32": (-2**31, 2**31 - 1, "-2**31..2**31-1"), "uint32": (0, 2**32 - 1, "0..2**32-1"),
    "int64": (-2**63, 2**63 - 1, "-2**63..2**63-1"), "uint64": (0, 2**64 - 1, "0..2**64-1"),
    "char": (0, 2**8 - 1, "0..255"), "byte": (-2**7, 2**7 - 1, "-128..127, as rosbags holds a byte"),
}
# numpy dtypes rosbags uses for arrays and sequences of each primitive kind.
_DTYPES = {"bool": "bool", "byte": "int8", "char": "uint8", "int8": "int8", "uint8": "uint8",
           "int16": "int16", "uint16": "uint16", "int32": "int32", "uint32": "uint32", "int64": "int64",
           "uint64": "uint64", "float32": "float32", "float64": "float64"}
_ONE_BYTE = frozenset({"byte", "char", "uint8", "int8"})  # bytes and bytearray fit arrays of these
# A float packs as float32 unless it rounds to infinity: from halfway past the largest float32 on.
_F32_LIMIT = 2.0**128 - 2.0**103
_F32_MAX = 3.4028234663852886e38
# An int converts to a float64 below halfway past the largest float.
_F64_INT_LIMIT = 2**1024 - 2**970


class Compiled(NamedTuple):
    """The compiled check of one message type."""

    fits: Callable[[object], bool]  # True: the value fits; False: ask ``explain``
    explain: _Explain  # None: the value fits; else where and why not
    prepare: _Prepare | None  # a fitting value as rosbags' serialiser takes it; None: as it is
    bounded: bool  # has bounded strings or sequences somewhere (rosbags' decoder does not check them)


def failure_text(failure: Failure) -> str:
    """``field a.b[2]: expected X, got Y`` (``expected X, got Y`` for the value itself)."""
    path, expected, found = failure
    where = f"field {path.lstrip('.')}: " if path else ""
    return f"{where}expected {expected}, got {found}"


def attr_name(field_name: str) -> str:
    """The attribute rosbags gives field ``field_name`` (a Python keyword gets a ``_``)."""
    return f"{field_name}_" if keyword.iskeyword(field_name) else field_name


def compile_message(name: str, cls: type, fields: Sequence[tuple[str, Any]],
                    nested: Callable[[str], Compiled]) -> Compiled:
    """The check of message ``name`` (rosbags class ``cls``, field definitions ``fields``).

    Args:
        nested: the compiled check of another message type, by name (for fields of message types).
    """
    compiled = [_compile_field(attr_name(field_name), description, nested) for field_name, description in fields]
    return Compiled(_class_fits(name, cls, compiled), _class_explain(name, cls, compiled),
                    _class_prepare(compiled), any(f.bounded for f in compiled))


class _Field(NamedTuple):
    """One field of a message, compiled."""

    attr: str
    # An expression true when the field's value surely fits, as a template: ``{x}`` is the value,
    # ``{n}`` the suffix of the names the expression uses (``names``, keys without the suffix).
    test: str
    names: dict[str, object]
    explain: _Explain
    prepare: _Prepare | None  # what rosbags' serialiser needs, from a fitting value; None: it is that
    bounded: bool


class _Unset:
    """What a field holds when its attribute is missing."""


_UNSET = _Unset()


def _describe(value: object) -> str:
    if value is _UNSET:
        return "no value (the attribute is not set)"
    if value is None:
        return "None"
    kind = type(value)
    msgtype = getattr(kind, "__msgtype__", None)
    if isinstance(msgtype, str):
        return msgtype
    if kind in (bool, int, float, str, bytes, bytearray):
        return f"{kind.__name__} {reprlib.repr(value)}"
    if isinstance(value, (list, tuple)) and kind in (list, tuple):
        return f"{kind.__name__} of {len(value)} items"
    dtype = getattr(value, "dtype", None)
    shape = getattr(value, "shape", None)
    if dtype is not None and shape == ():  # a numpy scalar
        return f"numpy {dtype} {reprlib.repr(value.item())}"  # type: ignore[attr-defined]
    if dtype is not None and shape is not None:
        return f"{kind.__name__} of {dtype}"
    return kind.__qualname__


def _compile_field(attr: str, description: tuple[Any, Any], nested: Callable[[str], Compiled]) -> _Field:
    node, detail = description
    if node == _BASE:
        kind, bound = detail
        test, explain = _scalar(kind, bound)
        return _Field(attr, test, {}, explain, None, bool(bound))
    if node == _NAME:
        inner = nested(detail)
        return _Field(attr, "_f{n}({x})", {"_f": inner.fits}, inner.explain, inner.prepare, inner.bounded)
    (item_node, item_detail), count = detail
    fixed = node == _ARRAY
    if item_node == _NAME:
        return _messages(attr, item_detail, nested(item_detail), count, fixed)
    kind, bound = item_detail
    if kind in _DTYPES:
        return _primitives(attr, kind, count, fixed)
    return _strings(attr, kind, bound, count, fixed)


def _scalar(kind: str, bound: int) -> tuple[str, _Explain]:
    import numpy as np

    if kind in _INTEGERS:
        low, high, span = _INTEGERS[kind]
        expected = f"{kind} ({span})"
        integers = (int, np.integer)

        def explain_int(x: object) -> Failure | None:
            if isinstance(x, bool) or not isinstance(x, integers):
                return ("", expected, _describe(x))
            return None if low <= x <= high else ("", expected, repr(int(x)))
        return f"(type({{x}}) is int and {low} <= {{x}} <= {high})", explain_int
    if kind in ("float32", "float64"):
        return _float(kind)
    if kind == "bool":
        def explain_bool(x: object) -> Failure | None:
            return None if isinstance(x, (bool, np.bool_)) else ("", "bool", _describe(x))
        return "type({x}) is bool", explain_bool
    return _string(kind, bound)


def _float(kind: str) -> tuple[str, _Explain]:
    import numpy as np

    wide = kind == "float64"
    reals = (float, np.floating)
    integers = (int, np.integer)

    def explain(x: object) -> Failure | None:
        if isinstance(x, reals):
            value = float(x)
            if wide or not math.isfinite(value) or abs(value) < _F32_LIMIT:
                return None
            return ("", f"{kind} (at most {_F32_MAX:.8g} in magnitude)", repr(value))
        if isinstance(x, integers) and not isinstance(x, bool):
            if abs(int(x)) < (_F64_INT_LIMIT if wide else _F32_LIMIT):
                return None
            return ("", f"{kind} (an int within its range)", reprlib.repr(int(x)))
        return ("", kind, _describe(x))
    test = "type({x}) is float" if wide else "(type({x}) is float and -_F32 <= {x} <= _F32)"
    return test, explain


def _string(kind: str, bound: int) -> tuple[str, _Explain]:
    spelled = f"{kind}<={bound}" if bound else kind

    def explain(x: object) -> Failure | None:
        if not isinstance(x, str):
            return ("", spelled, _describe(x))
        if x.isascii():
            size = len(x)
        else:
            try:
                size = len(x.encode())
            except UnicodeEncodeError:
                return ("", f"{spelled} (text UTF-8 can encode)", f"str {reprlib.repr(x)}")
        if bound and size > bound:
            return ("", f"{spelled} (at most {bound} bytes of UTF-8)", f"a str of {size} bytes")
        return None
    return "(type({x}) is str and {x}.isascii()" + (f" and len({{x}}) <= {bound})" if bound else ")"), explain


def _length(count: int, fixed: bool, spelled: str) -> tuple[str, Callable[[int], str | None]]:
    """The length test of an array or sequence (a test template), and why a length fails."""
    if fixed:
        return f" and len({{x}}) == {count}", lambda n: None if n == count else f"{count} items ({spelled})"
    if count:
        return f" and len({{x}}) <= {count}", lambda n: None if n <= count else f"at most {count} items ({spelled})"
    return "", lambda n: None


def _spelling(item: str, count: int, fixed: bool) -> str:
    return f"{item}[{count}]" if fixed else f"{item}[<={count}]" if count else f"{item}[]"


def _primitives(attr: str, kind: str, count: int, fixed: bool) -> _Field:
    import numpy as np

    dtype = np.dtype(_DTYPES[kind])
    also = np.dtype("uint8") if kind == "byte" else dtype  # the same octets; rosbags decodes int8
    spelled = _spelling(kind, count, fixed)
    expected = f"a sequence of {kind}" + ("" if spelled == f"{kind}[]" else f" ({spelled})")
    length_test, length_failure = _length(count, fixed, spelled)
    _, item_explain = _scalar(kind, 0)
    one_byte = kind in _ONE_BYTE
    ndarray = np.ndarray

    def explain(x: object) -> Failure | None:
        items: list[object] | tuple[object, ...] = ()
        if isinstance(x, ndarray):
            if x.dtype != dtype and x.dtype != also:
                return ("", expected, f"ndarray of {x.dtype}")
            if x.ndim != 1:
                return ("", f"a 1-D sequence of {kind}", f"ndarray of shape {x.shape}")
        elif isinstance(x, (bytes, bytearray)) and one_byte:
            pass
        elif isinstance(x, (list, tuple)):
            items = x
        else:
            return ("", expected, _describe(x))
        size = len(x)
        wrong = length_failure(size)
        if wrong is not None:
            return ("", wrong, str(size))
        for index, item in enumerate(items):
            failure = item_explain(item)
            if failure is not None:
                return (f"[{index}]", failure[1], failure[2])
        return None

    def prepare(x: Any) -> Any:
        if type(x) is ndarray and x.dtype == dtype and x.flags.c_contiguous:
            return x
        if isinstance(x, ndarray):
            return np.ascontiguousarray(x).view(dtype)  # a byte[] of uint8: the same octets
        if isinstance(x, (bytes, bytearray)):
            return np.frombuffer(x, dtype)
        return np.array(x, dtype=dtype)
    test = "(type({x}) is _nd and {x}.dtype == _dt{n} and {x}.ndim == 1" + length_test + ")"
    return _Field(attr, test, {"_dt": dtype}, explain, prepare, bool(count) and not fixed)


def _strings(attr: str, kind: str, bound: int, count: int, fixed: bool) -> _Field:
    item = f"{kind}<={bound}" if bound else kind
    spelled = _spelling(item, count, fixed)
    length_test, length_failure = _length(count, fixed, spelled)
    item_test, item_explain = _string(kind, bound)
    test = "(type({x}) is list and all(" + item_test.format(x="s") + " for s in {x})" + length_test + ")"
    return _Field(attr, test, {}, _items(f"a sequence of {item}", length_failure, item_explain), None,
                  bool(bound) or (bool(count) and not fixed))


def _messages(attr: str, name: str, inner: Compiled, count: int, fixed: bool) -> _Field:
    spelled = _spelling(name, count, fixed)
    length_test, length_failure = _length(count, fixed, spelled)
    test = "(type({x}) is list and all(map(_f{n}, {x}))" + length_test + ")"
    item_prepare = inner.prepare
    prepare: _Prepare | None = None
    if item_prepare is not None:
        def prepare(x: Any) -> Any:
            items = [item_prepare(item) for item in x]
            return x if all(a is b for a, b in zip(items, x, strict=True)) else items
    explain = _items(f"a sequence of {name}", length_failure, inner.explain)
    return _Field(attr, test, {"_f": inner.fits}, explain, prepare, inner.bounded or (bool(count) and not fixed))


def _items(expected: str, length_failure: Callable[[int], str | None], item_explain: _Explain) -> _Explain:
    """The check of a list or tuple whose items ``item_explain`` checks."""
    def explain(x: object) -> Failure | None:
        if not isinstance(x, (list, tuple)):
            return ("", expected, _describe(x))
        wrong = length_failure(len(x))
        if wrong is not None:
            return ("", wrong, str(len(x)))
        for index, item in enumerate(x):
            failure = item_explain(item)
            if failure is not None:
                return (f"[{index}]{failure[0]}", failure[1], failure[2])
        return None
    return explain


def _class_fits(name: str, cls: type, fields: list[_Field]) -> Callable[[object], bool]:
    """One generated function: true for exactly ``cls`` with every field of its commonest shape."""
    import numpy as np

    namespace: dict[str, object] = {"_cls": cls, "_nd": np.ndarray, "_F32": _F32_MAX}
    tests = ["type(value) is _cls"]
    for index, f in enumerate(fields):
        namespace.update((f"{key}{index}", value) for key, value in f.names.items())  # each field's own
        tests.append(f.test.format(x=f"value.{f.attr}", n=index))
    source = ("def fits(value):\n"
              "    try:\n"
              f"        return {' and '.join(tests)}\n"
              "    except Exception:\n"  # a missing attribute, say: the explanation says which
              "        return False\n")
    exec(compile(source, f"<ROS check of {name}>", "exec"), namespace)
    return namespace["fits"]  # type: ignore[return-value]


def _class_explain(name: str, cls: type, fields: list[_Field]) -> _Explain:
    checks = tuple((f.attr, f.explain) for f in fields)

    def explain(value: object) -> Failure | None:
        if not isinstance(value, cls):
            found = _describe(value)
            if found == name:  # the same name from another type store (a ROS 1 one, a registered one)
                found = f"{name} of another type store ({type(value).__module__})"
            return ("", name, found)
        for attr, check in checks:
            failure = check(getattr(value, attr, _UNSET))
            if failure is not None:
                return (f".{attr}{failure[0]}", failure[1], failure[2])
        return None
    return explain


def _class_prepare(fields: list[_Field]) -> _Prepare | None:
    steps = tuple((f.attr, f.prepare) for f in fields if f.prepare is not None)
    if not steps:
        return None

    def prepare(value: Any) -> Any:
        changed = None
        for attr, step in steps:
            old = getattr(value, attr)
            new = step(old)
            if new is not old:
                if changed is None:
                    changed = copy.copy(value)  # the caller's message stays as it was
                object.__setattr__(changed, attr, new)
        return value if changed is None else changed
    return prepare
