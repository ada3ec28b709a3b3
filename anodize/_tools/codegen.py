"""Typed endpoint modules: one Python class per state of a role's state machine.

For each global type and role, :func:`generate_module` writes a module that
wraps an ``anodize.Endpoint`` in typed *state objects*. A state class has
exactly the methods its state allows, and each method returns the next state,
so a type checker rejects an action the protocol does not allow at that point.
A state object can be used once (a second use raises ``LinearityError``).

Names in a generated module (all deterministic):

- module ``<global>_<role>.py`` in lower case (a prime ``'`` is spelled ``_prime``);
- ``State<n>``: state ``n`` of the role's machine; ``Initial`` is the start state
  and ``End`` the final one (when the type can end);
- a parallel branch ``i`` (from 1) has its own classes ``Branch<i>State<n>``
  (``State<k>Branch<i>State<n>`` when the machine has several forks, ``k`` the
  fork's state), nesting the same way;
- ``send_<label>``, ``recv_<label>``, ``select_<label>``: the label in snake case
  (``GoalPose`` -> ``goal_pose``, ``ok'`` -> ``ok_prime``); ``offer()`` and ``fork()``;
- ``offer()`` returns one frozen result class per label, ``<State><Label>``
  (``State2Deposit``), with fields ``payload`` (when the label carries one) and
  ``next_state``, so ``match`` works positionally: ``case State2Deposit(amount, s):``;
- at a choice among peers (``+{!B(m1), !C(m2)}``, ``&{?A(m1), ?C(x)}``) the names say
  the peer: ``select_<peer>_<label>`` (``select_b_m1``), and ``offer()`` (which takes
  the first message to come from any of them) returns ``<State>From<Peer><Label>``
  (``State0FromAM1``);
- named payloads (``quote(price: int, date: str)``) are a ``TypedDict`` per label,
  ``<Label>Fields`` (``QuoteFields``): the send method takes the fields as parameters
  (``send_quote(price, date)``, a field name that is not a Python name is spelled as
  a method name is, a keyword gets ``_2``), a receive returns the dict typed;
- time and value constraints (docs/decisions, "constraints in generated code"): each method's
  docstring says them in their canonical print; a refined payload's parameter is
  ``Annotated[T, "{predicate}"]`` (a record field: its own predicate); a send whose predicate
  names only its payload checks it before anything is sent (``_REFINEMENT<n>``, built once
  per module) and raises ``ProtocolViolationError`` blaming the role, the state staying
  unused; a receive with ``else timeout`` returns ``<State>Timeout`` (its ``next_state``: the
  same state again) when the endpoint gives the timeout (label ``"timeout"``).

Should two names still coincide, the later one gets ``_2``, ``_3``, ... .
"""

from __future__ import annotations

import hashlib
import keyword
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

from sessiontypes import Diagnostic, GlobalType, Location, ProtocolError, ProtocolModule, Sort, StateMachine, Transition
from sessiontypes import local_types as lt
from sessiontypes.constraints import Binary, Call, Compare, Expr, Number, Path, Text, Truth, Unary
from sessiontypes.refine import print_expr

from .._ros import DEFAULT_DISTRO, rosbags_class
from .._session import State
from .._session.timed import constraint_location

__all__ = [
    "GENERATOR_VERSION", "GeneratedModule", "CodegenError", "generate_modules",
    "generate_module", "module_filename", "input_digest", "snake_case",
]

# Part of every input digest: bump it whenever the generated text changes, so
# that `anodize project --check` reports modules from an older generator as stale.
GENERATOR_VERSION = "anodize-codegen 2"

_BUILTIN_TYPES = {"int": "int", "nat": "int", "bool": "bool", "str": "str", "float": "float",
                  "bytes": "bytes"}
# Generated modules import State from the package users import (anodize), not from where it is
# defined: that path is private and may move.
_STATE_IMPORT = f"from {__name__.partition('.')[0]} import {State.__name__} as _State"
# Names the generated text uses itself; nothing generated or imported may take them.
_RESERVED = frozenset({
    "annotations", "TYPE_CHECKING", "Any", "final", "dataclass", "Endpoint", "Message",
    "LinearityError", "Initial", "End", "_State", "int", "str", "bool", "float", "bytes",
    "tuple", "type", "AssertionError", "TimeoutError", "TypedDict", "Annotated",
    "_c", "_compile_predicate", "_Action", "_ProtocolViolationError", "_refused",
})
# The label a receive with ``else timeout`` gets when its deadline passes (anodize.TIMEOUT).
_TIMEOUT = "timeout"
# Characters of a refused payload the error quotes (as the monitor's).
_SHOWN = 120
# Docstrings quote the remaining local type; a very long one is cut here.
_MAX_TYPE_TEXT = 400


@dataclass(frozen=True, slots=True)
class GeneratedModule:
    """One generated module: its file name, what it was generated for, its text."""

    filename: str
    global_name: str
    role: str
    text: str


class CodegenError(ProtocolError):
    """Raised when a protocol cannot be turned into Python modules.

    That is when two (global, role) pairs would be written to the same file, or a
    ``type`` is bound to a Python name that cannot be imported (a keyword in it).

    Attributes:
        location: the global declaration concerned.
        message: what is wrong.
        source_line: the text of that line ("" when unknown).
    """

    def __init__(self, location: Location, message: str, source_line: str = "") -> None:
        self.location = location
        self.message = message
        self.source_line = source_line
        super().__init__(str(self))

    @property
    def diagnostics(self) -> tuple[Diagnostic, ...]:
        return (Diagnostic("error", self.location, self.message, self.source_line),)

    def __str__(self) -> str:
        return str(self.diagnostics[0])


def input_digest(source_text: str) -> str:
    """The sha256 (hex) of the generator version and the ``.proto`` text."""
    return hashlib.sha256(f"{GENERATOR_VERSION}\n{source_text}".encode()).hexdigest()


def module_filename(global_name: str, role: str) -> str:
    """``<global>_<role>.py`` in lower case, primes spelled ``_prime``."""
    return f"{global_name}_{role}".replace("'", "_prime").lower() + ".py"


def generate_modules(module: ProtocolModule, source_text: str,
                     targets: Iterable[tuple[GlobalType, str]] | None = None) -> list[GeneratedModule]:
    """Generate the modules of ``targets`` (default: every role of every global).

    Args:
        module: the checked protocol file.
        source_text: the exact text ``module`` was loaded from (for the digest).
        targets: (global type, role) pairs, in the order wanted.

    Returns:
        One :class:`GeneratedModule` per target, in order.

    Raises:
        CodegenError: two targets map to one file name, or a payload type cannot be imported.
        ProtocolError: a role is not a role of its global type.
    """
    if targets is None:
        targets = [(gt, role) for gt in module.globals.values() for role in gt.roles]
    digest = input_digest(source_text)
    generated: list[GeneratedModule] = []
    owners: dict[str, tuple[str, str]] = {}
    for global_type, role in targets:
        filename = module_filename(global_type.name, role)
        owner = owners.setdefault(filename, (global_type.name, role))
        if owner != (global_type.name, role):
            raise _error(global_type, f"global {owner[0]} role {owner[1]} and global "
                         f"{global_type.name} role {role} would both be written to {filename}; "
                         "rename one of them")
        text = generate_module(global_type, role, source_path=module.path, digest=digest)
        generated.append(GeneratedModule(filename, global_type.name, role, text))
    return generated


def generate_module(global_type: GlobalType, role: str, *, source_path: str, digest: str,
                    machine: StateMachine | None = None) -> str:
    """The text of the typed endpoint module of ``role`` in ``global_type``.

    Args:
        global_type: a checked global type.
        role: one of its roles.
        source_path: the ``.proto`` path to name in the header.
        digest: :func:`input_digest` of the ``.proto`` text.
        machine: the role's state machine, if not its projection's.

    Raises:
        CodegenError: a payload type is bound to a name Python cannot import.
        UnknownRoleError: ``role`` is not a role of ``global_type``.
    """
    if machine is None:
        machine = global_type.project(role).fsm()
    return _Writer(global_type, role, source_path, digest).write(machine)


def _error(global_type: GlobalType, message: str) -> CodegenError:
    location = global_type.location
    lines = global_type.source_lines
    line = lines[location.line - 1] if 0 < location.line <= len(lines) else ""
    return CodegenError(location, message, line)


# ---- names --------------------------------------------------------------------------

def snake_case(label: str) -> str:
    """The method-name form of a label: ``GoalPose`` -> ``goal_pose``, ``ok'`` -> ``ok_prime``."""
    text = re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", "_", label)
    return text.lower().replace("'", "_prime")


def _camel_case(label: str) -> str:
    words = snake_case(label).split("_")
    text = "".join(word[:1].upper() + word[1:] for word in words)
    # 'State1' + '2' would read as 'State12'.
    return text if text[:1].isalpha() else "_" + text


class _Names:
    """Hands out distinct names: a taken one gets ``_2``, ``_3``, ..."""

    def __init__(self, taken: Iterable[str] = ()) -> None:
        self.taken = set(taken)

    def claim(self, wanted: str) -> str:
        name, number = wanted, 1
        while name in self.taken or keyword.iskeyword(name):
            number += 1
            name = f"{wanted}_{number}"
        self.taken.add(name)
        return name


@dataclass
class _Machine:
    """A state machine of the role (the whole type, or a parallel branch) and its names."""

    machine: StateMachine
    where: str                      # "" or ", parallel branch 1.2"
    classes: dict[int, str] = field(default_factory=dict)
    branches: dict[int, list[_Machine]] = field(default_factory=dict)
    # (state, peer, label) -> the offer result's class / the method
    results: dict[tuple[int, str | None, str], str] = field(default_factory=dict)
    methods: dict[tuple[int, str | None, str], str] = field(default_factory=dict)


def _name_machine(machine: StateMachine, prefix: str, where: str, names: _Names) -> _Machine:
    named = _Machine(machine, where)
    for state in machine.states:
        named.classes[state] = names.claim(f"{prefix}State{state}")
    for state, parts in machine.forks.items():
        fork = f"{prefix}Branch" if len(machine.forks) == 1 else f"{prefix}State{state}Branch"
        named.branches[state] = [
            _name_machine(part, f"{fork}{index}",
                          f"{where}.{index}" if where else f", parallel branch {index}", names)
            for index, part in enumerate(parts, start=1)
        ]
    return named


def _name_members(named: _Machine, names: _Names) -> None:
    for state in named.machine.states:
        transitions = list(named.machine.table[state].values())
        methods = _Names()
        several = len({t.peer for t in transitions}) > 1  # a choice among peers: names say the peer
        for t in transitions:
            if len(transitions) == 1:
                verb = "send" if t.action == "send" else "recv"
            else:
                verb = "select" if t.action == "send" else "offer"
                if verb == "offer":
                    origin = f"From{_camel_case(t.peer or '')}" if several else ""
                    named.results[state, t.peer, t.label] = names.claim(
                        named.classes[state] + origin + _camel_case(t.label))
                    continue
            to = f"{snake_case(t.peer or '')}_" if several else ""
            named.methods[state, t.peer, t.label] = methods.claim(f"{verb}_{to}{snake_case(t.label)}")
    for parts in named.branches.values():
        for part in parts:
            _name_members(part, names)


def _all_machines(named: _Machine) -> list[_Machine]:
    found = [named]
    for parts in named.branches.values():
        for part in parts:
            found.extend(_all_machines(part))
    return found


def _escape(text: str) -> str:
    """Text that may sit inside a docstring or a comment on one line."""
    if text.isprintable() and "\\" not in text and '"' not in text:
        return text
    text = text.replace("\\", "\\\\").replace('"', '\\"')
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _quote(text: str | None) -> str:
    """A string literal (peers and labels are identifiers, possibly with primes)."""
    assert text is not None, "projections of global types always name the peer"
    return f'"{_escape(text)}"'


def _docstring(summary: str, notes: list[str]) -> list[str]:
    """A method's docstring: its summary line, then the notes (on the constraints) if any."""
    if not notes:
        return [f'        """{summary}"""']
    return [f'        """{summary}', "", *(f"        {note}" for note in notes), '        """']


def _paths(expr: Expr) -> list[Path]:
    """Every name ``expr`` reads."""
    if isinstance(expr, Path):
        return [expr]
    if isinstance(expr, Unary):
        return _paths(expr.operand)
    if isinstance(expr, Binary):
        return [*_paths(expr.left), *_paths(expr.right)]
    if isinstance(expr, Compare):
        return [p for operand in expr.operands for p in _paths(operand)]
    if isinstance(expr, Call):
        return [p for arg in expr.args for p in _paths(arg)]
    return []


def _expr_code(expr: Expr) -> str:
    """Python that builds ``expr`` (the module's ``_c`` is :mod:`sessiontypes.constraints`)."""
    if isinstance(expr, Number) and isinstance(expr.value, float) and not math.isfinite(expr.value):
        return f"_c.Number(float({str(expr.value)!r}))"  # 1e999 reads as inf, which has no literal
    if isinstance(expr, Number | Text | Truth):
        return f"_c.{type(expr).__name__}({expr.value!r})"
    if isinstance(expr, Path):
        return f"_c.Path({_tuple(repr(p) for p in expr.parts)})"
    if isinstance(expr, Unary):
        return f"_c.Unary({expr.op!r}, {_expr_code(expr.operand)})"
    if isinstance(expr, Binary):
        return f"_c.Binary({expr.op!r}, {_expr_code(expr.left)}, {_expr_code(expr.right)})"
    if isinstance(expr, Compare):
        return f"_c.Compare({_tuple(repr(op) for op in expr.ops)}, {_tuple(_expr_code(o) for o in expr.operands)})"
    return f"_c.Call({expr.function!r}, {_tuple(_expr_code(a) for a in expr.args)})"


def _tuple(items: Iterable[str]) -> str:
    found = list(items)
    return f"({found[0]},)" if len(found) == 1 else f"({', '.join(found)})"


def _refused_function(protocol: str, role: str) -> list[str]:
    """The module's ``_refused``: the error of a payload whose refinement is false, as the monitor words it."""
    return ["", "",
            "def _refused(state: str, expected: tuple[_Action, ...], peer: str, label: str, payload: object,",
            "             reason: str, location: str) -> _ProtocolViolationError:",
            f'    """A payload whose refinement is false: nothing was sent, and {_escape(role)} is blamed."""',
            "    shown = repr(payload)",
            f"    shown = shown if len(shown) <= {_SHOWN} else shown[:{_SHOWN - 3}] + \"...\"",
            '    actual = _Action("send", peer, label, type(payload).__name__)',
            (f"    return _ProtocolViolationError({_quote(protocol)}, {_quote(role)}, peer, state, expected, actual, "
             f'{_quote(role)}, location, f"{{reason}} for {{label}} {{shown}}")')]


# ---- writing ------------------------------------------------------------------------

class _Writer:
    def __init__(self, global_type: GlobalType, role: str, source_path: str, digest: str) -> None:
        self.global_type = global_type
        self.role = role
        self.source_path = source_path
        self.digest = digest
        self.imports: dict[tuple[str, str], str] = {}   # (module, top-level name) -> local name
        self.uses_any = False
        self.names = _Names(_RESERVED)
        self.actions: dict[int, str] = {}    # id(Send or Recv term) -> its single action's print
        self.records: dict[tuple[str, str], str] = {}   # (label, record sort key) -> its TypedDict
        self.record_lines: list[str] = []
        self.uses_annotated = False
        self.predicates: dict[Expr, str] = {}  # refinement -> the module's compiled predicate
        self.check_lines: list[str] = []
        self.record_fields: frozenset[str] = frozenset()  # every field name of the role's record payloads
        self.timeouts: list[str] = []  # the result classes of receives with ``else timeout``

    def write(self, machine: StateMachine) -> str:
        top = _name_machine(machine, "", "", self.names)
        _name_members(top, self.names)
        machines = _all_machines(top)
        self.record_fields = frozenset(f.name for t in machine.all_transitions()
                                       if t.sort is not None and t.sort.fields is not None for f in t.sort.fields)
        body: list[str] = []
        for named in machines:
            for state in named.machine.states:
                body.extend(self.state_class(named, state))
        exported = ["Initial"]
        finals = [s for s in machine.states if machine.is_final(s)]
        if finals:
            exported.append("End")
        exported += [c for named in machines for s in named.machine.states
                     for c in (named.classes[s], *self.result_names(named, s))]
        exported += self.timeouts
        exported += self.records.values()
        return "\n".join(self.head(machine, exported) + self.record_lines + self.check_lines + body
                         + self.tail(top, finals)) + "\n"

    def result_names(self, named: _Machine, state: int) -> list[str]:
        return [named.results[state, t.peer, t.label] for t in named.machine.table[state].values()
                if (state, t.peer, t.label) in named.results]

    def head(self, machine: StateMachine, exported: list[str]) -> list[str]:
        g, role = self.global_type.name, self.role
        typing_names = [*(["TYPE_CHECKING"] if self.imports else []), *(["Annotated"] if self.uses_annotated else []),
                        *(["Any"] if self.uses_any else []), *(["TypedDict"] if self.records else []), "final"]
        lines = [
            (f"# DO NOT EDIT: generated by anodize from {_escape(self.source_path)}, global {g}, "
             f"role {role}; input sha256 {self.digest}"),
            (f'"""Typed states of role {role} in global {g}: '
             f'``{self.type_text(machine, machine.initial)}``.'),
            "",
            "Start with ``Initial(endpoint)``. Each method performs the action it is named",
            "after and returns the next state; a state object can be used once.",
            '"""',
            "",
            "from __future__ import annotations",
            "",
            "from dataclasses import dataclass",
            f"from typing import {', '.join(typing_names)}",
            "",
            _STATE_IMPORT,
        ]
        if self.predicates:  # a refinement checked before sending: the same error the monitor raises
            lines += ["from anodize.errors import Action as _Action",
                      "from anodize.errors import ProtocolViolationError as _ProtocolViolationError",
                      "from sessiontypes import constraints as _c",
                      "from sessiontypes.refine import compile_predicate as _compile_predicate"]
        by_module: dict[str, list[str]] = {}
        for (module, name), local in sorted(self.imports.items()):
            by_module.setdefault(module, []).append(name if local == name else f"{name} as {local}")
        if by_module:
            lines += ["", "if TYPE_CHECKING:"]
            lines += [f"    from {module} import {', '.join(names)}"
                      for module, names in by_module.items()]
        lines += ["", "__all__ = ["]
        lines += [f'    "{name}",' for name in exported]
        lines += ["]"]
        return lines

    def tail(self, top: _Machine, finals: list[int]) -> list[str]:
        lines = ["", "", f"Initial = {top.classes[top.machine.initial]}"]
        if finals:
            lines.append(f"End = {top.classes[finals[0]]}")
        return lines

    def type_text(self, machine: StateMachine, state: int) -> str:
        """The remaining local type's canonical print, cut after ``_MAX_TYPE_TEXT`` characters.

        A long sequence is printed one message at a time, up to the cut: printing
        it whole for each of its states would take time quadratic in its length.
        """
        term = machine.terms[state]
        parts: list[str] = []
        size = 0
        while isinstance(term, (lt.Send, lt.Recv)) and size <= _MAX_TYPE_TEXT:
            part = self.actions.get(id(term))
            if part is None:
                part = self.actions[id(term)] = str(replace(term, continuation=lt.End()))
            parts.append(part)
            size += len(part) + 1
            term = term.continuation
        if size <= _MAX_TYPE_TEXT and not (parts and isinstance(term, lt.End)):
            parts.append(str(term))
        text = ".".join(parts)
        if size > _MAX_TYPE_TEXT or len(text) > _MAX_TYPE_TEXT:
            text = text[:_MAX_TYPE_TEXT] + " ..."
        return _escape(text)

    def payload_type(self, sort: Sort, label: str) -> str:
        if sort.fields is not None:
            return self.record(sort, label)
        if sort.target is None:
            return _BUILTIN_TYPES[sort.key]
        if sort.target.startswith("ros:"):
            _, kind, message = sort.target[4:].split("/")
            if kind != "msg":  # a service or an action: no message class to name
                self.uses_any = True
                return "Any"
            # rosbags' class of the message in the distribution the runtime checks payloads against.
            module, cls = rosbags_class(sort.target, DEFAULT_DISTRO)
            return self.imported(module, cls, message)
        module, qualified = sort.target.split(":")
        bad = [w for w in f"{module}.{qualified}".split(".") if keyword.iskeyword(w)]
        if bad:
            raise _error(self.global_type, f"type {sort.key} is bound to {sort.target!r}, which "
                         f"Python cannot import ('{bad[0]}' is a keyword)")
        top, *rest = qualified.split(".")
        return ".".join([self.imported(module, top, top), *rest])

    def record(self, sort: Sort, label: str) -> str:
        """The ``TypedDict`` of ``label``'s named payloads (defined on first use)."""
        assert sort.fields is not None
        name = self.records.get((label, sort.key))
        if name is None:
            name = self.records[label, sort.key] = self.names.claim(f"{_camel_case(label)}Fields")
            # The functional form: a field name need not be a Python name, and the types are
            # strings because the classes they name are imported for type checking only.
            items = ", ".join(f'"{_escape(f.name)}": "{self.payload_type(f.sort, label)}"' for f in sort.fields)
            self.record_lines += ["", "", f"# The fields of {_escape(label)}({_escape(sort.spelling)}).",
                                  f'{name} = TypedDict("{name}", {{{items}}})']
        return name

    def parameters(self, sort: Sort) -> list[tuple[str, str]]:
        """``(parameter, field name)`` for each field of a record sort, in order."""
        assert sort.fields is not None
        # Nothing the method's body names may be shadowed: the module's names, self, endpoint.
        names = _Names(self.names.taken | {"self", "endpoint", "_payload", "_reason"})
        return [(names.claim(f.name.replace("'", "_prime")), f.name) for f in sort.fields]

    def imported(self, module: str, name: str, wanted: str) -> str:
        """The local name of ``module.name`` (imported for typing), ``wanted`` unless it is taken."""
        local = self.imports.get((module, name))
        if local is None:
            local = self.imports[module, name] = self.names.claim(wanted)
        return local

    # ---- one state ----

    def state_class(self, named: _Machine, state: int) -> list[str]:
        machine = named.machine
        name = named.classes[state]
        transitions = list(machine.table[state].values())
        summary = (f"State {state} of role {self.role}{named.where}: "
                   f"``{self.type_text(machine, state)}``.")
        locations = list(dict.fromkeys(str(t.location) for t in transitions))
        if state in machine.forks and machine.terms[state].location.line > 0:
            locations = [str(machine.terms[state].location)]
        lines = ["", "", "@final", f"class {name}(_State):", f'    """{summary}']
        if locations:
            lines += ["", f"    Written at {_escape(', '.join(locations))}.", '    """']
        elif machine.is_final(state):
            lines += ["", "    The protocol has ended for this role: no action is left.", '    """']
        else:
            lines[-1] += '"""'
        lines += ["", "    __slots__ = ()"]
        results: list[str] = []
        assert len({t.action for t in transitions}) <= 1, "one direction"
        expiring = [t.timing for t in transitions if t.action == "recv" and t.timing is not None and t.timing.on_expiry]
        timeout = ""
        if expiring and state not in machine.forks:
            timeout = self.names.claim(f"{name}Timeout")
            self.timeouts.append(timeout)
            results += ["", "", "@final", "@dataclass(frozen=True, slots=True)", f"class {timeout}:",
                        (f'    """What ``{name}`` gives when ``{expiring[0]}`` passed with nothing arrived: '
                         '``next_state`` is that state again."""'), "", f"    next_state: {name}"]
        if state in machine.forks:
            lines += self.fork_method(named, state)
        elif len(transitions) == 1:
            lines += self.single_method(named, state, transitions[0], timeout)
        elif transitions and transitions[0].action == "send":
            for t in transitions:
                lines += self.single_method(named, state, t)
        elif transitions:
            lines += self.offer_method(named, state, transitions, timeout)
            for t in transitions:
                results += self.result_class(named, state, t)
        return lines + results

    def single_method(self, named: _Machine, state: int, t: Transition, timeout: str = "") -> list[str]:
        method = named.methods[state, t.peer, t.label]
        next_class = named.classes[t.target]
        checked = self.checked_here(t)
        doc = _docstring(f"``{_escape(str(t))}`` ({_escape(str(t.location))}).",
                         self.constraint_notes([t], checked, timeout))
        if t.action == "send":
            parameter, argument = "", ""
            if t.sort is not None and t.sort.fields is None:
                parameter, argument = f", payload: {self.refined_type(t.sort, t.label, t.refinement)}", "payload"
            if t.sort is not None and t.sort.fields is not None:
                self.payload_type(t.sort, t.label)  # its TypedDict is the module's, even if only sent
                pairs = list(zip(self.parameters(t.sort), t.sort.fields, strict=True))
                parameter = "".join(f", {p}: {self.refined_type(f.sort, t.label, f.refinement)}" for (p, _), f in pairs)
                argument = "{" + ", ".join(f'"{_escape(name)}": {p}' for (p, name), _ in pairs) + "}"
            lines = ["", f"    def {method}(self{parameter}) -> {next_class}:", *doc]
            if checked and t.refinement is not None:
                lines += self.refusal(named, state, t, t.refinement, argument)
                argument = "_payload"
            return [*lines, "        endpoint = self._use()",
                    f"        endpoint.send({_quote(t.peer)}, {_quote(t.label)}{', ' if argument else ''}{argument})",
                    f"        return {next_class}(endpoint)"]
        labels = f"({_quote(t.label)}, {_quote(_TIMEOUT)})" if timeout else f"({_quote(t.label)},)"
        receive = f"self._recv({_quote(t.peer)}, {labels}, timeout)"
        head = f"    def {method}(self, *, timeout: float | None = None) -> "
        expired = ([f"        if message.label == {_quote(_TIMEOUT)}:",
                    f"            return {timeout}({named.classes[state]}(self._endpoint))"] if timeout else [])
        otherwise = f" | {timeout}" if timeout else ""
        if t.sort is None:
            return ["", f"{head}{next_class}{otherwise}:", *doc, f"        message = {receive}" if timeout else
                    f"        {receive}", *expired, f"        return {next_class}(self._endpoint)"]
        return ["", f"{head}tuple[{self.payload_type(t.sort, t.label)}, {next_class}]{otherwise}:", *doc,
                f"        message = {receive}", *expired,
                f"        return message.payload, {next_class}(self._endpoint)"]

    # ---- constraints ----

    def checked_here(self, t: Transition) -> bool:
        """Whether the generated send checks ``t``'s refinement itself: it names nothing but its
        payload (a record's fields; a declared sort's attributes, no name being a record field
        the role sees, which could be an earlier payload's). Earlier payloads are the monitor's."""
        if t.action != "send" or t.refinement is None or t.sort is None:
            return False
        heads = {path.parts[0] for path in _paths(t.refinement)}
        if t.sort.fields is not None:
            return heads <= {f.name for f in t.sort.fields}
        return t.sort.target is not None and not heads & self.record_fields

    def constraint_notes(self, transitions: list[Transition], checked: bool, timeout: str) -> list[str]:
        """The docstring's sentences on the constraints of ``transitions`` (one action, or a choice's)."""
        timings = list(dict.fromkeys(str(t.timing) for t in transitions if t.timing is not None))
        refinements = list(dict.fromkeys(f"{{{print_expr(t.refinement)}}}" for t in transitions
                                         if t.refinement is not None))
        if not timings and not refinements:
            return []
        said = ", ".join(f"``{_escape(text)}``" for text in [*timings, *refinements])
        notes = [f"Constraints: {said}."]
        sending = transitions[0].action == "send"
        if refinements and sending and checked:
            notes.append(f"A payload for which the refinement is false is refused here, before anything is "
                         f"sent: ``ProtocolViolationError`` blaming {_escape(self.role)}, and this state stays unused.")
        elif refinements and sending:
            notes.append("The refinement names an earlier payload: the endpoint's monitor checks it.")
        elif refinements:
            notes.append("The endpoint's monitor checks the refinement on arrival (blaming the sender).")
        receivers_own = all(t.timing is None or (t.timing.on_expiry and t.timing.every is None) for t in transitions)
        if timings and sending and receivers_own:
            notes.append("With ``else timeout`` the deadline is the receiver's: nothing is timed on sending.")
        elif timings and not timeout:
            notes.append("The endpoint's monitor checks the time constraints (``DeadlineMissedError``).")
        if timeout:
            notes.append(f"When the deadline passes with nothing arrived: ``{timeout}`` (this state again).")
        return notes

    def refined_type(self, sort: Sort, label: str, refinement: Expr | None) -> str:
        """The parameter type of a payload (or field): ``Annotated`` with its refinement, if any."""
        plain = self.payload_type(sort, label)
        if refinement is None:
            return plain
        self.uses_annotated = True
        return f'Annotated[{plain}, "{_escape("{" + print_expr(refinement) + "}")}"]'

    def refusal(self, named: _Machine, state: int, t: Transition, refinement: Expr, payload: str) -> list[str]:
        """The lines of a send that check its payload's refinement before anything is sent."""
        check = self.predicate(refinement)
        machine = named.machine
        expected = ", ".join(
            f"_Action({_quote(e.action)}, {_quote(e.peer)}, {_quote(e.label)}, "
            f"{_quote(e.sort.spelling) if e.sort is not None else 'None'})" for e in machine.expected(state))
        where = _quote(f"{state} ({machine.describe(state)})")
        return [f"        _payload = {payload}",
                f"        _reason = {check}(_payload, {{}})",
                "        if _reason is not None:",
                (f"            raise _refused({where}, ({expected},), {_quote(t.peer)}, {_quote(t.label)}, "
                 f"_payload, _reason, {_quote(constraint_location(refinement, t))})")]

    def predicate(self, expr: Expr) -> str:
        """The module's compiled predicate of ``expr`` (written once, with ``_refused``)."""
        name = self.predicates.get(expr)
        if name is None:
            if not self.predicates:
                self.check_lines += _refused_function(self.global_type.name, self.role)
            name = self.predicates[expr] = self.names.claim(f"_REFINEMENT{len(self.predicates) + 1}")
            self.check_lines += ["", "", f"# {{{_escape(print_expr(expr))}}}",
                                 f"{name} = _compile_predicate({_expr_code(expr)})"]
        return name

    def offer_method(self, named: _Machine, state: int, transitions: list[Transition],
                     timeout: str = "") -> list[str]:
        peers = list(dict.fromkeys(t.peer for t in transitions))
        results = [named.results[state, t.peer, t.label] for t in transitions]
        where = _escape(", ".join(dict.fromkeys(str(t.location) for t in transitions)))
        choices = _escape(" | ".join(str(t) for t in transitions))
        doc = (f'``{_escape(peers[0] or "")}`` chooses: ``{choices}``' if len(peers) == 1
               else f"The first to arrive of ``{choices}``")
        returned = " | ".join([*results, *([timeout] if timeout else [])])
        lines = ["", f"    def offer(self, *, timeout: float | None = None) -> {returned}:",
                 *_docstring(f"{doc} ({where}).", self.constraint_notes(transitions, False, timeout))]
        if len(peers) == 1:
            labels = ", ".join(_quote(t.label) for t in [*transitions, *([replace(transitions[0], label=_TIMEOUT)]
                                                                         if timeout else [])])
            lines.append(f"        message = self._recv({_quote(peers[0])}, ({labels}), timeout)")
        else:  # the first message to come, from whichever of the peers
            pairs = ", ".join(f"({_quote(t.peer)}, {_quote(t.label)})" for t in transitions)
            if timeout:
                pairs += "".join(f", ({_quote(peer)}, {_quote(_TIMEOUT)})" for peer in peers)
            lines.append(f"        peer, message = self._recv_any(({pairs}), timeout)")
        if timeout:
            lines += [f"        if message.label == {_quote(_TIMEOUT)}:",
                      f"            return {timeout}({named.classes[state]}(self._endpoint))"]
        for index, (t, result) in enumerate(zip(transitions, results, strict=True)):
            payload = "message.payload, " if t.sort else ""
            value = f"{result}({payload}{named.classes[t.target]}(self._endpoint))"
            test = f"message.label == {_quote(t.label)}"
            if len(peers) > 1:
                test = f"peer == {_quote(t.peer)} and {test}"
            if index < len(transitions) - 1:
                lines += [f"        if {test}:",
                          f"            return {value}"]
            else:
                lines.append(f"        return {value}")
        return lines

    def result_class(self, named: _Machine, state: int, t: Transition) -> list[str]:
        name = named.results[state, t.peer, t.label]
        lines = ["", "", "@final", "@dataclass(frozen=True, slots=True)", f"class {name}:",
                 (f'    """What ``{named.classes[state]}.offer()`` returns when ``{_escape(str(t))}`` '
                  'arrived."""'), ""]
        if t.sort:
            lines.append(f"    payload: {self.payload_type(t.sort, t.label)}")
        lines.append(f"    next_state: {named.classes[t.target]}")
        return lines

    def fork_method(self, named: _Machine, state: int) -> list[str]:
        parts = named.branches[state]
        initials = [part.classes[part.machine.initial] for part in parts]
        variables = [f"branch{index}" for index in range(1, len(parts) + 1)]
        return ["", f"    def fork(self) -> tuple[{', '.join(initials)}]:",
                f'        """Split into {len(parts)} parallel branches, each with its own endpoint."""',
                "        endpoint = self._use()",
                f"        {', '.join(variables)} = endpoint.fork()",
                f"        return {', '.join(f'{c}({v})' for c, v in zip(initials, variables, strict=True))}"]
