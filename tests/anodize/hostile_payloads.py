"""Payloads whose own code attacks the endpoint that checks them, for test_hostile_payloads.py.

Each hook is a place where a payload (or the class a protocol declares as a sort) runs code of
its own while ``send`` or ``recv`` checks it: a metaclass's ``__hash__``, ``__eq__`` or
``__name__``, a ``__class__`` property, the sort class's ``__subclasscheck__``, a dataclass
field that is a property, ``__getattr__``. When one runs it applies :data:`PLAN` (delete or
replace attributes of the endpoint, its monitor or its outbox/inbox) to the endpoint in
:data:`TARGET`. :func:`run_case` drives one hostile message through either core and says
what happened, as text, so that a parent process can compare the cores after a crash too.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from collections.abc import Callable
from typing import Any

import sessiontypes
from anodize import RoleStopped
from anodize._session.endpoint import Endpoint
from anodize._transport.inproc import InprocNetwork
from anodize.errors import AnodizeError

PROTOCOL = """
type Record = "hostile_payloads:Record"
type Checked = "hostile_payloads:Checked"
type Probed = "hostile_payloads:Probed"
global G(A, B) = mu t. A -> B : { num(int). t, n(nat). t, record(Record). t, chk(Checked). t,
                                  probe(Probed{v > 0}). t, fin }
"""

# [(where, attribute, replacement)]: where is "endpoint", "monitor" or "channels" (the outbox of
# a sender, the inbox of a receiver: attribute is a peer); replacement a key of REPLACEMENTS.
PLAN: list[tuple[str, str, str]] = []
TARGET: dict[str, Any] = {}
FIRED: list[str] = []  # the hooks that ran


def _swap(where: str, attribute: str) -> object:
    other = TARGET["other"]
    holder = other if where == "endpoint" else other._monitor if where == "monitor" else None
    return getattr(holder, attribute, None) if holder is not None else TARGET["other"]._out.get("B")


REPLACEMENTS: dict[str, Callable[[str, str], object]] = {
    "delete": lambda where, attribute: None,  # not a value: the attribute is deleted
    "None": lambda where, attribute: None,
    "zero": lambda where, attribute: 0,
    "text": lambda where, attribute: "x",
    "empty dict": lambda where, attribute: {},
    "empty list": lambda where, attribute: [],
    "triple": lambda where, attribute: (1, 2, 3),
    "object": lambda where, attribute: object(),
    "the other endpoint's": _swap,
}


def fire(hook: str) -> None:
    """Apply PLAN to TARGET's endpoint (what a hostile payload's code does when it runs)."""
    FIRED.append(hook)
    endpoint = TARGET.get("endpoint")
    if endpoint is None:
        return
    for where, attribute, replacement in PLAN:
        try:
            if where == "channels":
                holder = getattr(endpoint, "_out" if TARGET["direction"] == "send" else "_in")
                if replacement == "delete":
                    holder.pop(attribute, None)
                else:
                    holder[attribute] = REPLACEMENTS[replacement](where, attribute)
                continue
            holder = endpoint if where == "endpoint" else endpoint._monitor
            if replacement == "delete":
                delattr(holder, attribute)
            else:
                setattr(holder, attribute, REPLACEMENTS[replacement](where, attribute))
        except (AttributeError, TypeError):  # already gone, or not a holder any more
            pass


# ---- the hooks -------------------------------------------------------------------------------

class LyingMeta(type):
    """A metaclass that says its classes are ``int`` (and runs code when asked)."""

    def __hash__(cls) -> int:
        fire("metaclass __hash__")
        return hash(int)

    def __eq__(cls, other: object) -> bool:
        fire("metaclass __eq__")
        return other is int or type.__eq__(cls, other) is True


class ClaimsInt(metaclass=LyingMeta):
    """Not an int, though its class compares equal to ``int``."""


class NamedMeta(type):
    """A metaclass whose ``__name__`` runs code (read for a violation's message)."""

    @property
    def __name__(cls) -> str:  # type: ignore[override]
        fire("metaclass __name__")
        return "int"


class Nameless(metaclass=NamedMeta):
    """Its class's name is code."""


class PosesAsInt:
    """Not an int, though its ``__class__`` says so (isinstance consults it)."""

    @property  # type: ignore[misc]
    def __class__(self) -> type:  # type: ignore[override]
        fire("__class__ property")
        return int


class CheckMeta(type):
    """The metaclass of a declared sort whose checks run code and accept anything."""

    def __instancecheck__(cls, instance: object) -> bool:
        fire("sort __instancecheck__")
        return True

    def __subclasscheck__(cls, subclass: type) -> bool:
        fire("sort __subclasscheck__")
        return True


class Checked(metaclass=CheckMeta):
    """The class of the sort ``Checked``."""


class Unrelated:
    """A payload for ``chk``: only Checked's own checks let it pass."""


@dataclasses.dataclass
class Record:
    """The class of the sort ``Record``: its field is checked on every message."""

    x: int


class PropertyRecord(Record):
    """A Record whose field is a property: reading it runs code."""

    @property  # type: ignore[misc]
    def x(self) -> int:  # type: ignore[override]
        fire("dataclass field property")
        return 1


class LazyRecord(Record):
    """A Record whose field is never set: ``__getattr__`` answers for it."""

    def __getattr__(self, name: str) -> object:
        fire("__getattr__")
        return 1


class Probed:
    """The class of the sort ``Probed``, refined by ``{v > 0}``: the refinement reads ``v``, a
    property, so code runs inside the check of a constrained step (in the compiled core too)."""

    @property
    def v(self) -> int:
        fire("refinement reads a property")
        return 1


class NegativeInt(int):
    """An int below zero that says it is not (for ``nat``)."""

    def __ge__(self, other: object) -> bool:
        fire("int subclass __ge__")
        return True

    def __lt__(self, other: object) -> bool:
        return False


def _payloads() -> dict[str, tuple[str, Callable[[], object]]]:
    return {
        "metaclass __hash__ and __eq__": ("num", ClaimsInt),
        "metaclass __name__": ("num", Nameless),
        "__class__ property": ("num", PosesAsInt),
        "sort __subclasscheck__": ("chk", Unrelated),
        "dataclass field property": ("record", lambda: object.__new__(PropertyRecord)),
        "__getattr__": ("record", lambda: object.__new__(LazyRecord)),
        "int subclass __ge__": ("n", lambda: NegativeInt(-5)),
        "field of a lying class": ("record", lambda: Record(ClaimsInt())),  # type: ignore[arg-type]
        "refinement reads a property": ("probe", Probed),
    }


HOOKS = tuple(_payloads())
_real_name = type.__dict__["__name__"].__get__  # not what a metaclass's __name__ says


# ---- driving one case ------------------------------------------------------------------------

class PythonEndpoint(Endpoint):
    """An endpoint on the Python core, whatever its base class."""

    send = Endpoint._send_python
    recv = Endpoint._recv_python


def _outcome(call: Callable[..., object], *args: object) -> list[str]:
    try:
        result = call(*args)
        if isinstance(result, tuple):  # a Message: its label and its payload's class (not its address)
            return ["returned", repr(result[0]), _real_name(type(result[1]))]
        return ["returned", repr(result)]
    except (Exception, RoleStopped) as error:  # compared, not handled
        return [type(error).__name__, str(error), "anodize" if isinstance(error, AnodizeError) else "other"]


def run_case(core: str, hook: str, direction: str, plan: list[tuple[str, str, str]]) -> list[list[str]]:
    """Send (or receive) the hook's payload with PLAN applied whenever its code runs, then an
    ordinary message: what each call returned or raised, on the ``core`` ("compiled" or "python")."""
    cls = Endpoint if core == "compiled" else PythonEndpoint
    protocol = sessiontypes.loads(PROTOCOL, "hostile.proto").globals["G"]
    machines = {role: protocol.project(role).fsm() for role in ("A", "B")}
    network = InprocNetwork([("A", "B"), ("B", "A")])
    sender, receiver = cls("A", "G", machines["A"], network), cls("B", "G", machines["B"], network)
    other = cls("A", "G", machines["A"], InprocNetwork([("A", "B"), ("B", "A")]))
    label, make = _payloads()[hook]
    PLAN[:] = plan
    TARGET.clear()
    FIRED.clear()
    TARGET.update(endpoint=sender if direction == "send" else receiver, other=other, direction=direction)
    outcomes = []
    if direction == "send":
        outcomes.append(_outcome(sender.send, "B", label, make()))
        PLAN.clear()
        outcomes.append(_outcome(sender.send, "B", "num", 1))
    else:
        channel = network.queues[("A", "B")]
        channel.put((label, make()))
        outcomes.append(_outcome(receiver.recv, "A"))
        PLAN.clear()
        channel.put(("num", 1))
        outcomes.append(_outcome(receiver.recv, "A"))
    TARGET.clear()
    return outcomes


def both_cores(hook: str, direction: str, plan: list[tuple[str, str, str]]) -> dict[str, object]:
    """:func:`run_case` on the Python core, then the compiled one, and the hooks that ran."""
    found: dict[str, object] = {}
    for core in ("python", "compiled"):
        found[core] = run_case(core, hook, direction, plan)
        found[f"{core} fired"] = sorted(set(FIRED))
    return found


def main() -> None:
    """``python -m hostile_payloads HOOK DIRECTION PLAN_JSON``: :func:`both_cores` as one JSON line."""
    hook, direction, plan = sys.argv[1], sys.argv[2], [tuple(step) for step in json.loads(sys.argv[3])]
    sys.stdout.write(json.dumps(both_cores(hook, direction, plan)) + "\n")
    sys.stdout.flush()


if __name__ == "__main__":  # run as the module the protocol's sorts import, not as a second copy
    import hostile_payloads

    hostile_payloads.main()
