"""Role parameters: typed values a role's function takes as keyword arguments.

The types are ROS 2's parameter types: ``bool``, ``int``, ``float``, ``str`` and arrays
of one of them (``list[float]``, ...). A role declares the parameters it takes as
keyword parameters of its function, with their types and defaults::

    def planner(ep: Endpoint, *, speed: float = 0.35, waypoints: list[int] = []) -> None: ...

and a system gives values (``System(g, params={"Planner": {"speed": 0.3}})``, a system
file's ``[params.Planner]``). Every value is checked against the function before the run
starts: a parameter the function does not take, or a value of another type, is refused
with the role, the parameter, what was expected and what was given.
"""

from __future__ import annotations

import inspect
import json
import types
import typing
from collections.abc import Callable, Mapping
from typing import Any, TypeAlias

from ..errors import ParameterError

__all__ = ["ParamValue", "check_value", "check_params", "type_name"]

ParamValue: TypeAlias = bool | int | float | str | list[bool] | list[int] | list[float] | list[str]

_SCALARS: tuple[type, ...] = (bool, int, float, str)


def type_name(value: object) -> str:
    """The ROS-style type of ``value``: ``float``, ``list[int]``, ``list`` (empty), else its Python type."""
    if isinstance(value, list):
        kinds = sorted({type_name(v) for v in value})
        return "list" if not kinds else f"list[{kinds[0]}]" if len(kinds) == 1 else f"list[{' | '.join(kinds)}]"
    return type(value).__name__


def check_value(role: str, name: str, value: object) -> ParamValue:
    """``value`` if it is a parameter value (a ROS parameter type), else why not.

    A list of ints and floats is a list of floats (as TOML writes ``[1, 2.5]``).

    Raises:
        ParameterError: not a bool, int, float, str, or a list of one of them.
    """
    if not name.isidentifier():
        raise ParameterError(role, name, "expected a name that is a Python identifier, such as speed")
    if isinstance(value, _SCALARS):
        return value  # type: ignore[return-value]  # one of the scalar members of ParamValue
    if isinstance(value, list):
        kinds = {type(v) for v in value}
        if kinds <= {int, float} and float in kinds:
            return [float(v) for v in value]
        if len(kinds) <= 1 and kinds <= set(_SCALARS):
            return list(value)
        raise ParameterError(role, name, "expected an array of one type (bool, int, float or str, as ROS "
                                         f"parameters), got {type_name(value)}")
    raise ParameterError(role, name, "expected a bool, int, float, str or an array of one of them (as ROS "
                                     f"parameters), got {type_name(value)}")


def check_params(role: str, function: Callable[..., Any], given: Mapping[str, object]) -> dict[str, ParamValue]:
    """The values ``given`` for ``role``, checked against its function's keyword parameters.

    An int given where the function declares a float becomes a float; nothing else is converted.

    Raises:
        ParameterError: a parameter the function does not take, a value not of its
            declared type, or a keyword-only parameter without a default that no value is given for.
    """
    values = {name: check_value(role, name, value) for name, value in given.items()}
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):  # a builtin without a signature: it takes whatever it is given
        return values
    hints = _hints(function)
    taken = {p.name: p for p in signature.parameters.values()
             if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}
    positional = [p for p in signature.parameters.values() if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    if positional:  # the first takes the endpoint (or the typed initial state), never a parameter
        taken.pop(positional[0].name, None)
    open_ended = any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values())
    shown = getattr(function, "__qualname__", repr(function))
    for name, value in values.items():
        if name not in taken:
            if open_ended:
                continue
            known = ", ".join(sorted(taken)) or "none"
            raise ParameterError(role, name, f"{shown} takes no such parameter; its parameters: {known}")
        expected = hints.get(name)
        if expected is not None:
            values[name] = _as_declared(role, name, value, expected)
    missing = sorted(n for n, p in taken.items() if p.kind is p.KEYWORD_ONLY and p.default is p.empty
                     and n not in values)
    if missing:
        raise ParameterError(role, missing[0], f"{shown} declares no default and no value is given "
                                               f"([params.{role}] {missing[0]} = ...)")
    return values


def _hints(function: Callable[..., Any]) -> dict[str, Any]:
    """The function's resolved annotations; those that cannot be resolved are not checked."""
    try:
        return typing.get_type_hints(function)
    except Exception:  # a forward reference that does not resolve: leave the types unchecked
        return {}


def _as_declared(role: str, name: str, value: ParamValue, expected: Any) -> ParamValue:
    """``value`` as the declared type ``expected`` (an int as a float), or a ParameterError."""
    options = typing.get_args(expected) if _is_union(expected) else (expected,)
    for option in options:
        converted = _fits(value, option)
        if converted is not None:
            return converted
    shown = " | ".join(_declared_name(o) for o in options)
    raise ParameterError(role, name, f"expected {shown}, got {type_name(value)} ({_literal(value)})")


def _fits(value: ParamValue, option: Any) -> ParamValue | None:
    if option is Any or option is object:
        return value
    if option in _SCALARS:
        if type(value) is option:
            return value
        if option is float and type(value) is int:
            return float(value)
        return None
    if typing.get_origin(option) is list and isinstance(value, list):
        (item,) = typing.get_args(option) or (Any,)
        converted = [_fits(v, item) for v in value]
        return None if any(c is None for c in converted) else converted  # type: ignore[return-value]
    return None


def _is_union(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)


def _declared_name(annotation: Any) -> str:
    if annotation is type(None):
        return "None"
    if isinstance(annotation, type) and not typing.get_args(annotation):
        return annotation.__name__
    return str(annotation).replace("typing.", "")


def _literal(value: ParamValue) -> str:
    text = json.dumps(value)  # as TOML writes it: true, "text", [1, 2]
    return text if len(text) <= 40 else text[:37] + "..."
