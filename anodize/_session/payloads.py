"""Checking payloads against the sorts of a protocol.

Builtin sorts map to Python types (``nat`` is an ``int >= 0``; ``float``
also takes an ``int``); a declared sort ``"module:QualifiedName"`` is checked
against that class, imported once when a monitor is built. A ROS 2 sort
(``"ros:pkg/msg/Name"``) is the message type of that name in ROS 2 Jazzy,
resolved through rosbags (:mod:`anodize._ros`): a payload must be an instance
of its rosbags class whose fields fit the definition, checked field by field
(ranges, array lengths, bounds, nested messages).

A dataclass payload is also checked field by field against its annotations
(see :func:`check_fields`), so a ``Point`` whose ``x: int`` holds a string is
the sender's violation, not a crash of the receiver later.

What a payload *is* comes from its real type, ``type(payload)``, compared by identity, never
from what the payload or its class says: ``__class__``, and a metaclass's ``__eq__`` and
``__hash__``, are not consulted (a class whose metaclass says it equals ``int`` is not an
``int``). The subclass policy, the same in both endpoint cores: a payload of exactly the
sort's class passes at once (the fast path, by identity); a real subclass (by the C-level
MRO) passes the full check; a sort's class may widen that with its own ``__subclasscheck__``
(an ABC's registered classes), which is the protocol's code, not the payload's.
"""

from __future__ import annotations

import collections.abc
import dataclasses
import importlib
import keyword
import reprlib
import sys
import types
import typing
from collections.abc import Callable, Iterable

from sessiontypes import Sort

from .._ros import ros_type  # rosbags itself is imported only when a ROS sort is resolved
from ..errors import AnodizeError

__all__ = ["Validator", "validator_for", "record_validator", "exact_types_for", "identities", "is_a", "real_name",
           "resolve_class", "with_field_classes", "check_fields"]

# A validator returns None when the payload fits, or why it does not.
Validator = Callable[[object], "str | None"]


def identities(types: Iterable[type]) -> frozenset[int]:
    """The identities of ``types``, for ``id(type(value)) in identities(...)``: a set of the types
    themselves would hash and compare them, and a metaclass may redefine both to pass for another
    class. Whoever keeps the set keeps the types alive too (an identity is only one while it lives)."""
    return frozenset(map(id, types))


def is_a(value: object, classes: type | tuple[type, ...]) -> bool:
    """Whether ``value``'s real type is one of ``classes`` or a subclass of one: ``isinstance``
    without consulting ``value.__class__`` (a property may say anything there)."""
    return issubclass(type(value), classes)


def real_name(cls: type) -> str:
    """A class's own ``__name__``, not what a metaclass's ``__name__`` property says."""
    return _type_name(cls)


_type_name: Callable[[type], str] = type.__dict__["__name__"].__get__


def _no_payload(payload: object) -> str | None:
    return None if payload is None else f"this label carries no payload, got {real_name(type(payload))}"


def _of(*types: type, name: str) -> Validator:
    def check(payload: object) -> str | None:
        kind = type(payload)
        if issubclass(kind, types) and not (kind is bool and bool not in types):
            return None
        return f"expected a payload of sort {name}, got {real_name(kind)}"
    return check


def _nat(payload: object) -> str | None:
    kind = type(payload)
    if issubclass(kind, int) and kind is not bool:
        number = typing.cast("int", payload)  # int's own comparison and text: a subclass may redefine both
        return None if int.__ge__(number, 0) else f"expected a payload of sort nat (>= 0), got {int.__repr__(number)}"
    return f"expected a payload of sort nat, got {real_name(kind)}"


_BUILTIN: dict[str, Validator] = {
    "int": _of(int, name="int"),
    "nat": _nat,
    "bool": _of(bool, name="bool"),
    "str": _of(str, name="str"),
    "float": _of(float, int, name="float"),
    "bytes": _of(bytes, name="bytes"),
}


def resolve_class(target: str) -> type:
    """Import the class named by ``"module:QualifiedName"``.

    Raises:
        AnodizeError: the module or the name cannot be found.
    """
    module_name, _, qualified = target.partition(":")
    try:
        value: object = importlib.import_module(module_name)
        for part in qualified.split("."):
            value = getattr(value, part)
    except (ImportError, AttributeError) as error:
        raise AnodizeError(f"cannot load payload class {target!r}: {error}") from None
    if not isinstance(value, type):
        raise AnodizeError(f"payload class {target!r} is not a class")
    return value


def with_field_classes(classes: Iterable[type]) -> list[type]:
    """``classes`` and every dataclass their dataclass fields are declared with, recursively.

    A sort such as ``PoseStamped`` names one class, but its fields hold a ``Header``
    and a ``Pose``: those are part of the message type the protocol names, so they
    may cross processes too (``tuple[PoseStamped, ...]`` fields count as well).
    """
    found: dict[type, None] = {}
    pending = list(classes)
    while pending:
        kind = pending.pop()
        if kind in found:
            continue
        found[kind] = None
        if dataclasses.is_dataclass(kind):
            try:
                hints = typing.get_type_hints(kind)
            except Exception:  # unresolvable annotations: keep the class, skip its fields
                continue
            for hint in hints.values():
                pending.extend(_dataclasses_in(hint))
    return list(found)


def _dataclasses_in(hint: object) -> list[type]:
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return [hint]
    return [k for arg in typing.get_args(hint) for k in _dataclasses_in(arg)]


def validator_for(sort: Sort | None) -> Validator:
    """The payload check for a transition carrying ``sort`` (None: no payload).

    For a class sort: an instance of the class, and if it is a dataclass, fields that fit
    their annotations (:func:`check_fields`). For a ROS 2 sort: :meth:`anodize._ros.RosType.check`.
    For named payloads (a record sort): a ``dict`` with exactly the record's field names,
    each value checked against its field's sort; the reason names the field.

    Raises:
        AnodizeError: the sort's class cannot be imported, or its ROS 2 type cannot be
            resolved (rosbags missing, no such message).
    """
    if sort is None:
        return _no_payload
    if sort.fields is not None:
        return _record(sort)
    if sort.target is None:
        return _BUILTIN[sort.key]
    if sort.target.startswith("ros:"):
        return ros_type(sort.target).check
    cls = resolve_class(sort.target)
    is_instance = _of(cls, name=f"{sort.spelling} ({sort.target})")
    fields = _fields_check(cls)  # compiled now: the first message should not pay for it

    def check(payload: object) -> str | None:
        reason = is_instance(payload)
        if reason is not None:
            return reason
        return check_fields(payload)  # a subclass's own fields count too
    chain = _CHAINS.get(cls) if fields is not None else None
    if chain is None:
        return check
    # The common case, an instance of the class whose fields all fit, in one call.
    test, namespace = chain
    return typing.cast("Validator", _generate(f"payload check of {cls.__qualname__}",
                                              f"type(value) is _cls and {test}", dict(namespace, _cls=cls), check,
                                              catch="(AttributeError, RecursionError)"))


def _record(sort: Sort) -> Validator:
    """Named payloads: a ``dict`` with exactly the record's field names, each value of its field's sort."""
    return record_validator(sort, validator_for)


def record_validator(sort: Sort, field_validator: Callable[[Sort], Validator]) -> Validator:
    """A record sort's check: a ``dict`` with exactly its field names, each value checked by
    ``field_validator`` of its field's sort (the monitors' checks, or a recording's by name)."""
    assert sort.fields is not None
    fields = tuple([(f.name, field_validator(f.sort)) for f in sort.fields])
    names = frozenset([name for name, _ in fields])
    wanted = f"a dict with the fields {sort.spelling}"

    def check(payload: object) -> str | None:
        if type(payload) is not dict:  # exactly a dict: what the transports carry as a dict
            return f"expected {wanted}, got {real_name(type(payload))}"
        for name, field_check in fields:
            if name not in payload:
                return f"field {name} is missing (expected {wanted})"
            reason = field_check(payload[name])
            if reason is not None:
                return f"field {name}: {reason}"
        if len(payload) != len(fields):
            extra = sorted(repr(key) for key in payload if key not in names)
            return f"unexpected field{'s' if len(extra) > 1 else ''} {', '.join(extra)} (expected {wanted})"
        return None
    return check


_EXACT: dict[str, frozenset[type]] = {
    "int": frozenset({int}), "bool": frozenset({bool}), "str": frozenset({str}),
    "float": frozenset({float, int}), "bytes": frozenset({bytes}),
}


def exact_types_for(sort: Sort | None) -> frozenset[type]:
    """Types whose instances fit ``sort`` without calling its validator (a fast path).

    Empty when every payload needs the full check: ``nat`` (which must be >= 0), a
    dataclass with annotated fields, a ROS 2 message and named payloads (their fields
    are checked on every message).
    """
    if sort is None:
        return frozenset({type(None)})
    if sort.fields is not None:  # every field is checked on every message
        for part in sort.fields:
            exact_types_for(part.sort)  # resolved now, as for a sort of its own
        return frozenset()
    if sort.target is None:
        return _EXACT.get(sort.key, frozenset())
    if sort.target.startswith("ros:"):
        ros_type(sort.target)  # resolved now, so that an unknown type fails when the monitor is built
        return frozenset()
    cls = resolve_class(sort.target)
    # A dataclass with checkable fields always takes the full check: its type alone says nothing
    # about what its fields hold.
    return frozenset() if _fields_check(cls) is not None else frozenset({cls})


# ---- dataclass fields ------------------------------------------------------------------------
# A compiled check returns None when the value fits, else (where below the value, what was
# expected there, what was found); the text is built only for a failure.
_Failure = tuple[str, str, object]
_Check = Callable[[object], "_Failure | None"]


class _Compiled(typing.NamedTuple):
    """One annotation, compiled once."""

    exact: frozenset[type]  # instances of these fit at once, without calling ``check``
    check: _Check | None  # the full check; None: anything fits
    name: str  # how the annotation reads in a message
    shallow: bool  # ``exact`` is what fitting values usually are (no walk into the value)


class _Unset:
    """What a field holds when its attribute was never set (an ``init=False`` field, say)."""


_UNSET = _Unset()
_ANYTHING = _Compiled(frozenset(), None, "Any", True)
_UNCOMPILED: typing.Any = object()
# Per class: its compiled field check, or None when there is nothing to check. Filled on first
# use and never emptied (payload classes are few and live as long as the program).
_CLASS_CHECKS: dict[type, _Check | None] = {}
# Per class with a compiled field check: its chain of type tests (true when every field fits,
# reading the class instance as ``value``) and the names the chain uses.
_CHAINS: dict[type, tuple[str, dict[str, object]]] = {}
_NONE_TYPE = type(None)
_REPR_TYPES = (bool, int, float, complex, str, bytes, bytearray, list, tuple, dict, set, frozenset)
_REPR_TYPE_IDS = identities(_REPR_TYPES)


def check_fields(value: object) -> str | None:
    """Why the fields of dataclass instance ``value`` do not fit their annotations (None: they do).

    Checked: builtin classes (an ``int`` fits ``float`` and ``complex``, a ``bool`` fits only
    ``bool``, as for the builtin sorts; a subclass fits its base), any other class (:func:`is_a`),
    ``X | None`` and other unions, ``Literal[...]``, ``list[T]``, ``tuple[T, ...]``, ``tuple[A, B]``,
    ``set[T]``, ``frozenset[T]``, ``dict[K, V]`` (and their ``collections.abc`` counterparts),
    nested dataclasses (recursively), ``np.ndarray`` and ``npt.NDArray[dtype]`` (an ndarray, and
    its dtype where one is given). Accepted unchecked: ``Any``, ``object``, type variables,
    protocols, annotations that do not resolve, and other special forms. Not a dataclass: None.

    Each class's annotations are resolved once (``typing.get_type_hints``) and compiled into
    one check, cached per class.
    """
    kind = type(value)
    check = _CLASS_CHECKS.get(kind, _UNCOMPILED)
    if check is _UNCOMPILED:
        check = _fields_check(kind)
    return None if check is None else _run_fields(kind, check, value)


def _run_fields(kind: type, check: _Check, value: object) -> str | None:
    try:
        failure = check(value)
    except RecursionError:
        return f"{_name_of(kind)} is nested too deeply to check (does it contain itself?)"
    if failure is None:
        return None
    path, expected, found = failure
    return f"field {path.lstrip('.')} of {_name_of(kind)}: expected {expected}, got {_describe(found)}"


def _fields_check(cls: type) -> _Check | None:
    """The compiled field check of ``cls`` (None: not a dataclass, or nothing to check)."""
    check = _CLASS_CHECKS.get(cls, _UNCOMPILED)
    if check is _UNCOMPILED:
        check = _CLASS_CHECKS[cls] = _compile_class(cls) if dataclasses.is_dataclass(cls) else None
    return check  # type: ignore[no-any-return]


def _compile_class(cls: type) -> _Check | None:
    hints = _hints_of(cls)
    shallow: list[tuple[str, frozenset[type], _Check]] = []
    deep: list[tuple[str, _Check]] = []
    for f in dataclasses.fields(cls):
        try:
            compiled = _compile(hints.get(f.name, typing.Any))
        except Exception:  # an annotation too exotic to compile: accepted unchecked
            continue
        if compiled.check is None:
            continue
        if compiled.shallow and compiled.exact:
            shallow.append((f.name, compiled.exact, compiled.check))
        else:
            deep.append((f.name, compiled.check))
    if not shallow and not deep:
        return None
    slow = _field_by_field(tuple(shallow), tuple(deep))
    names = [name for name, _, _ in shallow] + [name for name, _ in deep]
    if not all(name.isidentifier() and not keyword.iskeyword(name) for name in names):
        return slow
    # The check runs on every message: as dataclasses does for __init__, compile one function
    # for the class, a chain of type tests that is true when everything fits. Anything else
    # (a misfit, a subclass, an unset attribute) takes the field-by-field check, which says why.
    namespace: dict[str, object] = {}
    tests = []
    for index, (name, exact, _) in enumerate(shallow):
        if len(exact) == 1:
            namespace[f"_t{index}"] = next(iter(exact))
            tests.append(f"type(value.{name}) is _t{index}")
        else:
            namespace[f"_e{index}"] = identities(exact)
            tests.append(f"id(type(value.{name})) in _e{index}")
    for index, (name, field_check) in enumerate(deep):
        namespace[f"_d{index}"] = field_check
        tests.append(f"_d{index}(value.{name}) is None")
    _CHAINS[cls] = (" and ".join(tests), namespace)
    return typing.cast("_Check", _generate(f"field check of {cls.__qualname__}", _CHAINS[cls][0], namespace, slow))


def _generate(title: str, test: str, namespace: dict[str, object], otherwise: Callable[[object], object],
              catch: str = "AttributeError") -> Callable[[object], object]:
    """``def check(value)``: None when the expression ``test`` is true, else ``otherwise(value)``.

    An exception in ``catch`` (an unset field) also leads to ``otherwise``. Only the outermost
    check may catch RecursionError: were every level to retry, a cycle would cost 2**depth.
    """
    source = ("def check(value):\n"
              "    try:\n"
              f"        if {test}:\n"
              "            return None\n"
              f"    except {catch}:\n"
              "        pass\n"
              "    return _otherwise(value)\n")
    scope = dict(namespace, _otherwise=otherwise)
    exec(compile(source, f"<{title}>", "exec"), scope)
    return typing.cast("Callable[[object], object]", scope["check"])


def _field_by_field(shallow: tuple[tuple[str, frozenset[type], _Check], ...],
                    deep: tuple[tuple[str, _Check], ...]) -> _Check:
    known = tuple((name, identities(exact), field_check) for name, exact, field_check in shallow)

    def check(value: object) -> _Failure | None:
        for name, exact, field_check in known:
            item = getattr(value, name, _UNSET)
            if id(type(item)) not in exact and (failure := field_check(item)) is not None:
                return (f".{name}{failure[0]}", failure[1], failure[2])
        for name, field_check in deep:
            failure = field_check(getattr(value, name, _UNSET))
            if failure is not None:
                return (f".{name}{failure[0]}", failure[1], failure[2])
        return None
    return check


def _hints_of(cls: type) -> dict[str, object]:
    try:
        return typing.get_type_hints(cls)
    except Exception:  # one annotation does not resolve: resolve the others one by one
        pass
    module = sys.modules.get(cls.__module__)
    namespace = dict(vars(module)) if module is not None else {}
    hints: dict[str, object] = {}
    for f in dataclasses.fields(cls):
        hint: object = f.type
        if isinstance(hint, str):
            try:  # what get_type_hints does with a string annotation: the class's own source text
                hint = eval(hint, namespace, dict(vars(cls)))
            except Exception:
                hint = typing.Any  # unresolvable (a TYPE_CHECKING import, say): accepted unchecked
        hints[f.name] = hint
    return hints


_UNWRAP = (typing.Final, typing.Annotated, typing.ClassVar)
_SEQUENCES: dict[object, type] = {
    list: list, collections.abc.Sequence: collections.abc.Sequence,
    collections.abc.MutableSequence: collections.abc.MutableSequence}
_SETS: dict[object, type] = {
    set: set, frozenset: frozenset, collections.abc.Set: collections.abc.Set,
    collections.abc.MutableSet: collections.abc.MutableSet}
_MAPPINGS: dict[object, type] = {
    dict: dict, collections.abc.Mapping: collections.abc.Mapping,
    collections.abc.MutableMapping: collections.abc.MutableMapping}


def _compile(hint: object) -> _Compiled:
    if hint is typing.Any or hint is object:
        return _ANYTHING
    if hint is None or hint is _NONE_TYPE:
        return _Compiled(frozenset({_NONE_TYPE}), _is_none, "None", True)
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is typing.Union or origin is types.UnionType:
        return _union([_compile(arg) for arg in args])
    if origin is typing.Literal:
        return _literal(args)
    if origin in _UNWRAP:
        return _compile(args[0]) if args else _ANYTHING
    if origin is not None:
        return _generic(origin, args)
    if isinstance(hint, typing.NewType):
        return _compile(hint.__supertype__)
    if isinstance(hint, type):
        return _class(hint)
    return _ANYTHING  # a type variable, an unresolved forward reference, another special form


def _is_none(value: object) -> _Failure | None:
    return None if value is None else ("", "None", value)


def _class(cls: type) -> _Compiled:
    if dataclasses.is_dataclass(cls):
        return _Compiled(frozenset(), _nested(cls), _name_of(cls), False)
    if getattr(cls, "_is_protocol", False):  # isinstance either fails or only looks for methods
        return _ANYTHING
    name = _name_of(cls)
    accepted: tuple[type, ...] = _NUMERIC_TOWER.get(cls, (cls,))
    if cls in _NUMERIC_TOWER:  # a bool is an int to Python, not to a protocol (as for the builtin sorts)
        def check(value: object) -> _Failure | None:
            if issubclass(type(value), accepted) and type(value) is not bool:
                return None
            return ("", name, value)
    else:
        def check(value: object) -> _Failure | None:
            return None if is_a(value, accepted) else ("", name, value)
    return _Compiled(frozenset(accepted), check, name, True)


# As for the builtin sorts: an int fits a float (and both fit a complex); a bool fits none of them.
_NUMERIC_TOWER: dict[type, tuple[type, ...]] = {int: (int,), float: (float, int), complex: (complex, float, int)}


def _nested(cls: type) -> _Check:
    name = _name_of(cls)
    own: list[_Check | None] = []  # cls's check, compiled on first use: a dataclass may contain itself

    def check(value: object) -> _Failure | None:
        if type(value) is cls:
            if not own:
                own.append(_fields_check(cls))
            fields = own[0]
        elif is_a(value, cls):
            fields = _fields_check(type(value))
        else:
            return ("", name, value)
        return None if fields is None else fields(value)
    return check


def _union(options: list[_Compiled]) -> _Compiled:
    if any(option.check is None for option in options):
        return _ANYTHING
    name = " | ".join(option.name for option in options)
    exact = frozenset().union(*(option.exact for option in options))
    exact_ids = identities(exact)
    checks = tuple(option.check for option in options if option.check is not None)

    def check(value: object) -> _Failure | None:
        if id(type(value)) in exact_ids:
            return None
        deeper = None
        for option in checks:
            failure = option(value)
            if failure is None:
                return None
            if failure[0] and deeper is None:  # the value is of this option, a part of it is not
                deeper = failure
        return deeper or ("", name, value)
    return _Compiled(exact, check, name, all(option.shallow for option in options))


def _literal(values: tuple[object, ...]) -> _Compiled:
    name = " | ".join(repr(v) for v in values)

    def check(value: object) -> _Failure | None:
        kind = type(value)
        if any(kind is type(v) and value == v for v in values):
            return None
        return ("", name, value)
    return _Compiled(frozenset(), check, name, False)


def _generic(origin: object, args: tuple[object, ...]) -> _Compiled:
    np = sys.modules.get("numpy")
    if np is not None and origin is np.ndarray:
        return _array(np, args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return _items(tuple, _compile(args[0]), f"tuple[{_compile(args[0]).name}, ...]", indexed=True)
        return _fixed_tuple([_compile(arg) for arg in args])
    if origin in _SEQUENCES:
        item = _compile(args[0]) if args else _ANYTHING
        kind = _SEQUENCES[origin]
        return _items(kind, item, f"{kind.__name__}[{item.name}]", indexed=True)
    if origin in _SETS:
        item = _compile(args[0]) if args else _ANYTHING
        kind = _SETS[origin]
        return _items(kind, item, f"{kind.__name__}[{item.name}]", indexed=False)
    if origin in _MAPPINGS:
        key, value = (_compile(args[0]), _compile(args[1])) if len(args) == 2 else (_ANYTHING, _ANYTHING)
        return _mapping(_MAPPINGS[origin], key, value)
    if isinstance(origin, type):  # deque[int], type[X], Callable[...]: the class only, not its arguments
        if getattr(origin, "_is_protocol", False):
            return _ANYTHING
        kind = origin
        name = _name_of(kind)

        def check(value: object) -> _Failure | None:
            return None if is_a(value, kind) else ("", name, value)
        return _Compiled(frozenset({kind}), check, name, True)
    return _ANYTHING


def _items(kind: type, item: _Compiled, name: str, indexed: bool) -> _Compiled:
    item_exact, item_check = item.exact, item.check
    if item_check is None:
        def whole(value: object) -> _Failure | None:
            return None if is_a(value, kind) else ("", name, value)
        return _Compiled(frozenset({kind}) if kind in (list, tuple, set, frozenset) else frozenset(),
                         whole, name, True)
    item_ids = identities(item_exact)
    fits = item_ids.__contains__

    def check(value: object) -> _Failure | None:
        if not is_a(value, kind):
            return ("", name, value)
        elements = typing.cast("Iterable[object]", value)  # ``kind`` is an iterable class
        if all(map(fits, map(id, map(type, elements)))):
            return None
        for index, element in enumerate(elements):
            if id(type(element)) not in item_ids and (failure := item_check(element)) is not None:
                # A set has no index to show: the whole set is what did not fit.
                return (f"[{index}]{failure[0]}", failure[1], failure[2]) if indexed else ("", name, value)
        return None
    return _Compiled(frozenset(), check, name, False)


def _fixed_tuple(items: list[_Compiled]) -> _Compiled:
    name = f"tuple[{', '.join(item.name for item in items) or '()'}]"
    size = len(items)
    steps = tuple((identities(item.exact), item.check) for item in items)

    def check(value: object) -> _Failure | None:
        if not is_a(value, tuple):
            return ("", name, value)
        elements = typing.cast("tuple[object, ...]", value)  # tuple's own length and items: a subclass may lie
        if tuple.__len__(elements) != size:
            return ("", name, value)
        for index, (exact, item_check) in enumerate(steps):
            element = tuple.__getitem__(elements, index)
            if item_check is not None and id(type(element)) not in exact and (failure := item_check(element)):
                return (f"[{index}]{failure[0]}", failure[1], failure[2])
        return None
    return _Compiled(frozenset(), check, name, False)


def _mapping(kind: type, key: _Compiled, item: _Compiled) -> _Compiled:
    name = f"{kind.__name__}[{key.name}, {item.name}]"
    key_exact, key_check = identities(key.exact), key.check
    item_exact, item_check = identities(item.exact), item.check

    def check(value: object) -> _Failure | None:
        if not is_a(value, kind):
            return ("", name, value)
        for k, v in value.items():  # type: ignore[attr-defined]
            if key_check is not None and id(type(k)) not in key_exact and key_check(k) is not None:
                return ("", name, value)  # a key that does not fit: the whole mapping is shown
            if item_check is not None and id(type(v)) not in item_exact and (failure := item_check(v)):
                return (f"[{k!r}]{failure[0]}", failure[1], failure[2])
        return None
    return _Compiled(frozenset(), check, name, False)


def _array(np: typing.Any, args: tuple[object, ...]) -> _Compiled:
    ndarray = np.ndarray
    scalar: object = None
    if len(args) == 2 and typing.get_origin(args[1]) is np.dtype and typing.get_args(args[1]):
        scalar = typing.get_args(args[1])[0]
        scalar = typing.get_origin(scalar) or scalar  # np.floating[Any] -> np.floating
    if not isinstance(scalar, type):  # no dtype given (Any, a type variable): any ndarray fits
        def any_array(value: object) -> _Failure | None:
            return None if is_a(value, ndarray) else ("", "ndarray", value)
        return _Compiled(frozenset({ndarray}), any_array, "ndarray", True)
    kind = scalar
    name = f"ndarray of {kind.__name__}"

    def check(value: object) -> _Failure | None:
        if is_a(value, ndarray) and issubclass(typing.cast("typing.Any", value).dtype.type, kind):
            return None
        return ("", name, value)
    return _Compiled(frozenset(), check, name, False)


def _name_of(cls: type) -> str:
    """``cls``'s qualified name, without the ``f.<locals>.`` of a class made in a function."""
    return _real_qualname(cls).rpartition("<locals>.")[2]


_real_qualname: Callable[[type], str] = type.__dict__["__qualname__"].__get__


def _describe(value: object) -> str:
    """``value`` in a violation's reason: its type, and for plain data a short repr."""
    if value is _UNSET:
        return "no value (the attribute was never set)"
    if value is None:
        return "None"
    kind = type(value)
    if id(kind) in _REPR_TYPE_IDS:
        return f"{kind.__name__} {reprlib.repr(value)}"
    np = sys.modules.get("numpy")
    if np is not None and is_a(value, np.ndarray):
        return f"ndarray of {typing.cast('typing.Any', value).dtype}"
    return _name_of(kind)
