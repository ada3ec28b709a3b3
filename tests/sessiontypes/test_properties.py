"""Property tests for the .proto language (LANGUAGE.md): parse/print round trips,
projection against an independent global semantics, and robustness of loads.

The generated protocols come from ``strategies.py`` (projectable by
construction); the reference semantics is ``global_semantics.py``.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, example, given, note, settings
from hypothesis import strategies as st

# The helper modules live beside this file (no package: tests have no __init__.py).
_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

from budget import examples  # noqa: E402
from global_semantics import GlobalSemantics, SearchBoundExceededError, restrict  # noqa: E402
from strategies import GeneratedGlobal, global_protocols, mutated_texts, protocol_texts  # noqa: E402

import sessiontypes  # noqa: E402
from sessiontypes import GlobalType, ProjectionError, ProtocolError, StateMachine  # noqa: E402
from sessiontypes import global_types as g  # noqa: E402
from sessiontypes.printer import print_global  # noqa: E402
from sessiontypes.sorts import Interaction  # noqa: E402

# Example counts keep the whole file under about 25 s (65 generated protocols per property: each
# CI run tries the same ones, each dev run new ones); the thorough profile multiplies them
# (`pytest --hypothesis-profile=thorough`, see tests/conftest.py).
SETTINGS = settings(deadline=None, max_examples=examples(65),
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _load_global(text: str) -> GlobalType:
    return sessiontypes.loads(text, "generated.proto").globals["G"]


def _choice(sender: str, receiver: str, *branches: tuple[str, g.GlobalTerm]) -> g.GlobalTerm:
    return g.Choice(sender, receiver, tuple(g.Branch(Interaction(label), rest) for label, rest in branches))


# ---- minimal reproducers of bugs these properties found -----------------------------------

# A loop between A and B that C never joins, entered after C's only message.
# LANGUAGE.md 5: "mu t. G onto r is mu t. (G↾r) when r occurs in G, else end",
# so C's projection is !A(l0). Was rejected (t merged with end) before 6f38a60.
LOOP_WITHOUT_C = GeneratedGlobal(
    "global G = C -> A : l0. mu t. A -> B : {l0. t, l1. end}",
    _choice("C", "A", ("l0", g.Rec("t", _choice("A", "B", ("l0", g.Var("t")), ("l1", g.End()))))),
    ("C", "A", "B"))

# Roles are "those that occur, in order of first occurrence" (LANGUAGE.md 2):
# A, B, C, D here. Before 6f38a60 the second branch's roles came first (A, B, D, C).
ROLES_IN_SECOND_BRANCH_FIRST = GeneratedGlobal(
    "global G = A -> B : {l0. A -> C : l1. A -> D : l1, l1. A -> D : l2. A -> C : l2}",
    _choice("A", "B",
            ("l0", _choice("A", "C", ("l1", _choice("A", "D", ("l1", g.End()))))),
            ("l1", _choice("A", "D", ("l2", _choice("A", "C", ("l2", g.End())))))),
    ("A", "B", "C", "D"))


# A role that sends in a loop it reaches in both branches, the loop's variable
# named differently in each: was rejected ("only identical behaviours merge unless
# both receive": mu t.!B(l1).t versus mu u.!B(l1).u). The same with one name
# for both loops, or with A receiving, was accepted. Projectability must not
# depend on bound variable names: alpha-equivalent types are identical.
RENAMED_SENDING_LOOP = GeneratedGlobal(
    "global G = B -> C : {l0. mu t. A -> B : l1. t, l1. mu u. A -> B : l1. u}",
    _choice("B", "C",
            ("l0", g.Rec("t", _choice("A", "B", ("l1", g.Var("t"))))),
            ("l1", g.Rec("u", _choice("A", "B", ("l1", g.Var("u")))))),
    ("B", "C", "A"))


# ---- 1. parse and print ------------------------------------------------------------------

@pytest.mark.slow
@SETTINGS
@given(global_protocols(constrained=True))
def test_parse_builds_the_generated_term(generated: GeneratedGlobal) -> None:
    """Every spelling of the language (ASCII/Unicode, message forms, braces,
    parentheses, comments) parses to the term it denotes."""
    note(generated.text)
    assert _load_global(generated.text).body == generated.body


@pytest.mark.slow
@SETTINGS
@example(ROLES_IN_SECOND_BRANCH_FIRST)
@given(global_protocols(constrained=True))
def test_roles_are_declared_order_or_first_occurrence(generated: GeneratedGlobal) -> None:
    """A global's roles are its role list, or those that occur in source order."""
    note(generated.text)
    assert _load_global(generated.text).roles == generated.roles


@pytest.mark.slow
@SETTINGS
@given(global_protocols(constrained=True))
def test_global_print_parse_round_trip(generated: GeneratedGlobal) -> None:
    """``print_global`` reads back as the same term, and printing is stable."""
    original = _load_global(generated.text)
    printed = print_global(original.body)
    note(printed)
    again = _load_global("global G = " + printed)
    assert again.body == original.body
    assert print_global(again.body) == printed
    # the whole declaration, with its role list, too
    declared = sessiontypes.loads(str(original)).globals["G"]
    assert (declared.roles, declared.body) == (original.roles, original.body)


@pytest.mark.slow
@SETTINGS
@given(global_protocols(constrained=True))
def test_local_canonical_print_round_trip(generated: GeneratedGlobal) -> None:
    """The canonical print of every projection parses back as the same local type."""
    global_type = _load_global(generated.text)
    for role in global_type.roles:
        projected = global_type.project(role)
        printed = str(projected)
        note(f"{role} = {printed}")
        module = sessiontypes.loads(f"local L at {role} = {printed}")
        parsed = module.locals["L"]
        assert parsed.body == projected.body
        assert str(parsed) == printed


# ---- 2. projection -------------------------------------------------------------------------

@pytest.mark.slow
@SETTINGS
@example(LOOP_WITHOUT_C)
@example(RENAMED_SENDING_LOOP)
@given(global_protocols(constrained=True))
def test_projection_never_fails(generated: GeneratedGlobal) -> None:
    """Generated protocols are projectable by construction (strategies._Generator):
    loads accepts them and every role gets a local type and a state machine."""
    note(generated.text)
    note(print_global(generated.body))
    global_type = _load_global(generated.text)
    for role in global_type.roles:
        global_type.project(role).fsm()


# A configuration of a machine: its state and, in a fork state, one
# configuration per parallel branch.
@dataclass(frozen=True)
class Config:
    machine: StateMachine
    state: int
    branches: tuple[Config, ...] = ()

    @staticmethod
    def enter(machine: StateMachine, state: int) -> Config:
        forks = machine.forks.get(state)
        if forks is None:
            return Config(machine, state)
        return Config(machine, state, tuple(Config.enter(m, m.initial) for m in forks))

    @property
    def is_fork(self) -> bool:
        return self.state in self.machine.forks

    def is_final(self) -> bool:
        if self.is_fork:
            return all(b.is_final() for b in self.branches)
        return self.machine.is_final(self.state)

    def enabled(self) -> list[tuple]:
        if self.is_fork:
            return [e for b in self.branches for e in b.enabled()]
        return [(t.action, t.peer, t.label, t.sort) for t in self.machine.expected(self.state)]

    def step(self, local_event: tuple) -> Config | None:
        """Take ``(action, peer, label, sort)``; None if not allowed (or wrong sort)."""
        action, peer, label, sort = local_event
        if self.is_fork:
            moved = [(i, after) for i, b in enumerate(self.branches)
                     if (after := b.step(local_event)) is not None]
            assert len(moved) <= 1, f"{local_event} is allowed by several parallel branches"
            if not moved:
                return None
            (index, after), = moved
            return Config(self.machine, self.state,
                          (*self.branches[:index], after, *self.branches[index + 1:]))
        transition = self.machine.step(self.state, action, peer, label)
        if transition is None or transition.sort != sort:
            return None
        return Config.enter(self.machine, transition.target)

    def describe(self) -> str:
        if self.is_fork:
            return "(" + " || ".join(b.describe() for b in self.branches) + ")"
        return self.machine.describe(self.state)


def _machines(generated: GeneratedGlobal) -> dict[str, tuple[str, StateMachine]]:
    """Each role's canonical print and machine (roles that do not project are
    left to test_projection_never_fails)."""
    global_type = GlobalType("G", generated.roles, generated.body)
    machines = {}
    for role in generated.roles:
        try:
            projected = global_type.project(role)
        except ProjectionError:
            event("a role does not project")
            continue
        machines[role] = (str(projected), projected.fsm())
    return machines


def _show(local_event: tuple) -> str:
    action, peer, label, sort = local_event
    return f"{'!' if action == 'send' else '?'}{peer}({label}{'(' + str(sort) + ')' if sort else ''})"


@pytest.mark.slow
@SETTINGS
@given(global_protocols(constrained=True), st.randoms(use_true_random=False))
def test_machines_accept_every_global_run(generated: GeneratedGlobal, rng) -> None:
    """(i) The restriction of a global run to a role is a trace of its machine,
    and a run that reaches ``end`` leaves every machine final."""
    note(print_global(generated.body))
    semantics = GlobalSemantics(generated.body)
    machines = _machines(generated)
    for _ in range(8):
        run, state = semantics.random_run(rng, rng.randint(0, 30))
        for role, (printed, machine) in machines.items():
            config = Config.enter(machine, machine.initial)
            seen: list[str] = []
            for interaction in run:
                local_event = restrict(interaction, role)
                if local_event is None:
                    continue
                after = config.step(local_event)
                assert after is not None, (
                    f"{role} = {printed}: after {'.'.join(seen) or 'nothing'} the machine "
                    f"(at {config.describe()}) refuses {_show(local_event)}; "
                    f"global run {[f'{p}->{q}:{label}' for p, q, label, _ in run]}")
                seen.append(_show(local_event))
                config = after
            if semantics.is_final(state):
                assert config.is_final(), (
                    f"{role} = {printed}: the global run ended but the machine expects "
                    f"{config.describe()} after {'.'.join(seen)}")


@pytest.mark.slow
@SETTINGS
@given(global_protocols(constrained=True), st.randoms(use_true_random=False))
def test_machine_walks_are_global_prefixes(generated: GeneratedGlobal, rng) -> None:
    """(ii) Every walk of a role's machine is a prefix of the restriction of some
    global run, and the machine is final exactly when no such run lets the role act again."""
    note(print_global(generated.body))
    semantics = GlobalSemantics(generated.body)
    for role, (printed, machine) in _machines(generated).items():
        for _ in range(4):
            config = Config.enter(machine, machine.initial)
            word: list[tuple] = []
            for _ in range(rng.randint(0, 12)):
                options = config.enabled()
                if not options:
                    break
                choice = options[rng.randrange(len(options))]
                after = config.step(choice)
                assert after is not None, f"{role}: the machine refuses its own {_show(choice)}"
                word.append(choice)
                config = after
            try:
                matched, more = semantics.explore_prefix(role, word)
            except SearchBoundExceededError:
                event("search bound hit")
                continue
            shown = ".".join(map(_show, word)) or "(empty)"
            assert matched, f"{role} = {printed}: the walk {shown} is not in any global run"
            assert config.is_final() == (not more), (
                f"{role} = {printed}: after {shown} the machine is "
                f"{'final' if config.is_final() else 'not final'} but the role "
                f"{'can' if more else 'cannot'} act again in the global type")


# ---- 3. robustness -------------------------------------------------------------------------

# str() of a check error lists warnings too, so the error need not come first.
_ERROR_HEAD = re.compile(r"^fuzz\.proto:\d+:\d+: error: ", re.MULTILINE)


@pytest.mark.slow
@settings(SETTINGS, max_examples=examples(150))
@given(protocol_texts() | mutated_texts())
def test_loads_raises_only_protocol_errors(text: str) -> None:
    """Any text either loads or raises a ProtocolError whose text says 'error'."""
    try:
        module = sessiontypes.loads(text, "fuzz.proto")
    except ProtocolError as error:
        message = str(error)
        repr(error)
        assert "error" in message
        if isinstance(error, (sessiontypes.ProtocolSyntaxError, sessiontypes.ProtocolCheckError)):
            assert _ERROR_HEAD.search(message), message
        return
    for global_type in module.globals.values():
        str(global_type)
        for role in global_type.roles:
            projected = global_type.project(role)
            str(projected)
            projected.fsm()
    for local in module.locals.values():
        str(local)
        local.fsm()


@pytest.mark.parametrize("text", ["global", "global G = A -> A : x", "local L = !B(x",
                                  "global G = mu t. t", "/*", '"', "type T = \"x"])
def test_loads_error_examples(text: str) -> None:
    with pytest.raises(ProtocolError) as info:
        sessiontypes.loads(text, "fuzz.proto")
    assert "error" in str(info.value)
