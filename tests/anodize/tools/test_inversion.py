"""The priority-inversion analysis of `anodize lint`: protocols built to have inversions (direct,
through three groups, through a bounded channel's send), protocols built free of them, CPU sets,
external roles and hosts, and a property over random small protocols."""

from __future__ import annotations

import itertools
import json
import random
import re
from collections import deque
from collections.abc import Iterable
from pathlib import Path
from unittest import mock

import networkx as nx
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import sessiontypes
from anodize import Dds, Processes, RosBridge
from anodize._tools import chains, inversion
from anodize._tools.chains import Chains, ChainSearch
from anodize._tools.cli import main
from anodize._tools.config import GroupConfig, SystemConfig
from anodize._tools.inversion import Inversion, InversionReport, Preemption, analyse_inversions
from anodize._tools.lint import LintReport
from anodize._tools.waits import Wait

REPO = Path(__file__).resolve().parents[3]

ASK_REPLY = "global AskReply(H, L) = mu t. H -> L : ask. L -> H : reply. t"
CHAIN = "global Chain(H, M, L) = mu t. H -> M : ask. M -> L : ask. L -> M : reply. M -> H : reply. t"
PUSH = "global Push(H, L) = mu t. H -> L : data. t"
RELAY = "global Relay(H, M, L) = mu t. H -> M : data. M -> L : data. t"

Groups = dict[str, tuple[int | None, tuple[str, ...], tuple[int, ...] | None]]


def system(groups: Groups, external: tuple[str, ...] = (), capacities: dict[str, int] | None = None,
           hosts: dict[str, str] | None = None, inheritance: bool = False) -> SystemConfig:
    """A checked system file's value: group name -> (priority, roles, CPUs). Priority inheritance is
    turned off in every group unless ``inheritance``: most tests here are about what it leaves open."""
    table = {name: GroupConfig(name, priority, None, cpus, "stop", 3, dict.fromkeys(roles, "m:f"),
                               f"system.toml: groups.{name}", (hosts or {}).get(name), inheritance)
             for name, (priority, roles, cpus) in groups.items()}
    transport = Dds() if external or hosts else Processes()
    return SystemConfig(Path("system.toml"), Path("p.proto"), "G", transport, None, True, (), table,
                        ros=RosBridge(external=frozenset(external)) if external else None,
                        capacities=capacities or {})


def analyse(protocol: str, config: SystemConfig) -> InversionReport:
    module = sessiontypes.loads(protocol)
    return analyse_inversions(config, next(iter(module.globals.values())))


def pairs(report: InversionReport) -> list[tuple[str, str]]:
    return [(i.high.role, i.low.role) for i in report.inversions]


HIGH_MEDIUM_LOW: Groups = {"high": (90, ("H",), None), "medium": (50, ("Spinner",), None), "low": (10, ("L",), None)}


def test_a_reply_from_a_lower_group_is_an_unbounded_inversion_while_inheritance_is_not_applied() -> None:
    report = analyse(ASK_REPLY, system(HIGH_MEDIUM_LOW))
    [found] = report.inversions
    assert found.chain == (Wait("H", "1", "L", "recv", "?L(reply)"),)
    assert [p.describe() for p in found.parties] == ["H (group high, priority 90, CPUs any)",
                                                      "L (group low, priority 10, CPUs any)"]
    assert found.preemptions == (Preemption("medium", 50, None, "L"),)
    assert (found.uncoverable, found.unbounded) == (
        ("H waits on group low, which turns it off (priority_inheritance = false)",),
        ("medium can preempt L for as long as it runs",))
    assert report.unbounded == (found,)
    assert (report.waits, report.inheritance_applied) == (2, False)


def test_the_whole_block_of_text() -> None:
    report = analyse(ASK_REPLY, system(HIGH_MEDIUM_LOW))
    assert report.lines() == [
        "unbounded inversion: H (group high, priority 90, CPUs any) can wait on L (group low, priority 10, CPUs any)",
        "  chain: H ?L(reply) [state 1] -> L",
        "  roles: H (group high, priority 90, CPUs any), L (group low, priority 10, CPUs any)",
        "  preempted by: medium (priority 50, CPUs any) over L",
        ("  priority inheritance: cannot cover it: H waits on group low, which turns it off "
         "(priority_inheritance = false)"),
        "  unbounded: medium can preempt L for as long as it runs",
        "1 priority inversion (1 unbounded) among 2 waits; priority inheritance is turned off in some groups",
    ]


def test_a_chain_through_three_groups_is_found_with_every_link() -> None:
    groups: Groups = {"high": (90, ("H",), None), "medium": (50, ("M",), None), "low": (10, ("L",), None)}
    report = analyse(CHAIN, system(groups))
    assert pairs(report) == [("H", "M"), ("H", "L"), ("M", "L")]
    through = report.inversions[1]
    assert through.chain == (Wait("H", "1", "M", "recv", "?M(reply)"), Wait("M", "2", "L", "recv", "?L(reply)"))
    assert [p.role for p in through.parties] == ["H", "M", "L"]
    assert through.preemptions == (Preemption("medium", 50, None, "L"),)
    # H -> M alone has nothing preempting M, but M can wait on L, and that is unbounded
    assert report.inversions[0].preemptions == ()
    assert report.inversions[0].unbounded == ("M can itself wait on L, and that is unbounded (see H -> L)",)


def test_a_send_on_a_bounded_channel_waits_on_its_receiver() -> None:
    groups: Groups = {"high": (90, ("H",), None), "low": (10, ("L",), None)}
    assert analyse(PUSH, system(groups)).inversions == ()
    [found] = analyse(PUSH, system(groups, capacities={"H->L": 4})).inversions
    assert found.chain == (Wait("H", "0", "L", "send", "!L(data)"),)
    assert found.bounded  # no group between 10 and 90


def test_a_chain_through_a_bounded_channels_send() -> None:
    groups: Groups = {"high": (90, ("H",), None), "medium": (50, ("M",), None), "low": (10, ("L",), None)}
    report = analyse(RELAY, system(groups, capacities={"H->M": 1, "M->L": 1}))
    assert pairs(report) == [("H", "M"), ("H", "L"), ("M", "L")]
    assert report.inversions[1].chain == (Wait("H", "0", "M", "send", "!M(data)"),
                                          Wait("M", "1", "L", "send", "!L(data)"))
    # only H's channel bounded: M never blocks on L, so H's wait on M goes no further
    assert pairs(analyse(RELAY, system(groups, capacities={"H->M": 1}))) == [("H", "M")]


def test_waits_only_downwards_are_no_inversion() -> None:
    # L waits on H (upwards); H never waits: its channel is unbounded
    assert analyse(PUSH, system({"high": (90, ("H",), None), "low": (10, ("L",), None)})).inversions == ()
    # a pipeline from high to low: each role waits only on the one above it
    groups: Groups = {"high": (90, ("H",), None), "medium": (50, ("M",), None), "low": (10, ("L",), None)}
    report = analyse(RELAY, system(groups))
    assert (report.inversions, report.waits) == ((), 2)


def test_the_same_group_or_the_same_priority_is_no_inversion() -> None:
    assert analyse(ASK_REPLY, system({"one": (90, ("H", "L"), None), "other": (50, ("X",), None)})).inversions == ()
    assert analyse(ASK_REPLY, system({"a": (50, ("H",), None), "b": (50, ("L",), None)})).inversions == ()
    assert analyse(ASK_REPLY, system({"a": (None, ("H",), None), "b": (None, ("L",), None)})).inversions == ()


@pytest.mark.parametrize(("medium", "low", "preempted"), [
    ((0,), (1,), False),   # kept off the low group's CPU
    ((1,), (1,), True),    # on it
    ((0, 1), (1,), True),  # sharing one of them
    (None, (1,), True),    # no CPU set: may run anywhere
    ((0,), None, True),    # the low group may run anywhere, so also where medium runs
])
def test_cpu_sets_decide_who_can_preempt_the_low_group(
        medium: tuple[int, ...] | None, low: tuple[int, ...] | None, preempted: bool) -> None:
    groups: Groups = {"high": (90, ("H",), (0,)), "medium": (50, ("Spinner",), medium), "low": (10, ("L",), low)}
    [found] = analyse(ASK_REPLY, system(groups)).inversions
    assert bool(found.preemptions) is preempted
    assert found.bounded is not preempted


def test_groups_above_the_waiter_or_below_the_low_role_do_not_count() -> None:
    groups: Groups = {"top": (95, ("X",), None), "high": (90, ("H",), None), "low": (10, ("L",), None),
                      "bottom": (5, ("Y",), None), "plain": (None, ("Z",), None)}
    [found] = analyse(ASK_REPLY, system(groups)).inversions
    assert (found.preemptions, found.bounded) == ((), True)


def test_a_low_role_without_a_priority_is_delayed_by_anything() -> None:
    [found] = analyse(ASK_REPLY, system({"high": (90, ("H",), None), "low": (None, ("L",), None)})).inversions
    assert found.unbounded == ("L has no real-time priority: any process on the machine can delay it",)


def test_a_wait_on_an_external_ros_node_is_unbounded_and_inheritance_cannot_cover_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    config = system({"high": (90, ("H",), None)}, external=("L",))
    [found] = analyse(ASK_REPLY, config).inversions
    assert found.low.describe() == "L (external ROS 2 node, priority unknown)"
    assert found.uncoverable == ("H waits on external ROS 2 node L",)
    assert found.unbounded == ("L is an external ROS 2 node: its priority and timing are unknown",)
    assert not analyse(ASK_REPLY, config).inversions[0].bounded


def test_a_wait_on_a_group_on_another_host_is_unbounded() -> None:
    config = system({"high": (90, ("H",), None), "low": (10, ("L",), None)}, hosts={"high": "robot", "low": "base"})
    [found] = analyse(ASK_REPLY, config).inversions
    assert found.uncoverable == ("H waits on group low on host base across the network, from host robot",)
    assert found.unbounded == ("L runs on host base: no inheritance crosses hosts",)


def test_inheritance_applied_bounds_a_wait_a_medium_group_could_stretch() -> None:
    report = analyse(ASK_REPLY, system(HIGH_MEDIUM_LOW, inheritance=True))
    assert report.inheritance_applied
    assert report.inversions[0].bounded
    assert report.lines()[-3:] == [
        "  priority inheritance: covers it (every link on one host, to a group anodize runs that accepts it); applied",
        "  unbounded: nothing (the wait is bounded by the lower roles' own work)",
        "1 priority inversion (0 unbounded) among 2 waits; priority inheritance is applied"]


def test_a_wait_in_another_parallel_branch_does_not_stretch_this_one() -> None:
    groups: Groups = {"high": (90, ("H",), None), "medium": (50, ("L",), None), "low": (10, ("M",), None)}
    # L waits on M in its second branch; it answers H from its first, which that wait does not hold up
    parallel = "global Par(H, L, M) = ( mu a. H -> L : go. L -> H : done. a || mu b. M -> L : tick. b )"
    report = analyse(parallel, system(groups))
    assert pairs(report) == [("H", "L"), ("L", "M")]
    assert report.inversions[0].chain == (Wait("H", "1", "L", "recv", "?L(done)"),)
    assert report.inversions[1].chain == (Wait("L", "0.2.0", "M", "recv", "?M(tick)"),)
    # in sequence, the same wait does hold H up
    sequential = "global Seq(H, L, M) = mu a. H -> L : go. M -> L : tick. L -> H : done. a"
    assert pairs(analyse(sequential, system(groups))) == [("H", "L"), ("H", "M"), ("L", "M")]


# ---- the property: over random small protocols, exactly the waits from higher to lower -----------

Interaction = tuple[int, int]


@st.composite
def protocols(draw: st.DrawFn) -> tuple[str, SystemConfig, list[str], list[Interaction], bool, set[Interaction]]:
    count = draw(st.integers(2, 4))
    roles = [f"R{i}" for i in range(count)]
    pairs_ = st.tuples(st.integers(0, count - 1), st.integers(0, count - 1)).filter(lambda p: p[0] != p[1])
    steps = draw(st.lists(pairs_, min_size=1, max_size=7).filter(
        lambda s: {r for p in s for r in p} == set(range(count))))
    loop = draw(st.booleans())
    body = " ".join(f"{roles[a]} -> {roles[b]} : m{i}." for i, (a, b) in enumerate(steps))
    text = f"global G({', '.join(roles)}) = " + (f"mu t. {body} t" if loop else f"{body} end")
    bounded = draw(st.sets(st.sampled_from(sorted(set(steps)))))
    priorities = st.sampled_from([None, 10, 30, 50, 90])
    group_of = draw(st.lists(st.integers(0, 2), min_size=count, max_size=count))
    groups: Groups = {}
    for g in sorted(set(group_of)):
        groups[f"g{g}"] = (draw(priorities), tuple(r for r, h in zip(roles, group_of, strict=True) if h == g), None)
    config = system(groups, capacities={f"{roles[a]}->{roles[b]}": 1 for a, b in bounded})
    return text, config, roles, steps, loop, bounded


def oracle(roles: list[str], steps: list[Interaction], loop: bool, bounded: set[Interaction],
           rank: dict[str, int], group: dict[str, str]) -> dict[tuple[str, str], int]:
    """Written from the global sequence, not the state machines: (high, low) -> the shortest chain's length."""
    actions = {r: [(i, a, b) for i, (a, b) in enumerate(steps) if r in (roles[a], roles[b])] for r in roles}
    # wait = (role, index of its action, peer, kind); released by the peer's later (or, in a loop, any) action
    waits = []
    for role, mine in actions.items():
        for k, (_, a, b) in enumerate(mine):
            if roles[b] == role:
                waits.append((role, k, roles[a], "recv"))
            elif (a, b) in bounded:
                waits.append((role, k, roles[b], "send"))

    def stretches(first: tuple[str, int, str, str], second: tuple[str, int, str, str]) -> bool:
        role, _, peer, kind = first
        if second[0] != peer:
            return False
        later = actions[peer] if loop else actions[peer][second[1]:]
        wanted = (peer, role) if kind == "recv" else (role, peer)  # the peer sends to, or receives from, role
        return any((roles[a], roles[b]) == wanted for _, a, b in later)

    found: dict[tuple[str, str], int] = {}
    for start in waits:
        queue = deque([(start, 1, frozenset({start[0], start[2]}))])
        while queue:
            wait, length, seen = queue.popleft()
            high, low = start[0], wait[2]
            if rank[low] < rank[high]:
                found[high, low] = min(found.get((high, low), length), length)
            for following in waits:
                if stretches(wait, following) and following[2] not in seen:
                    queue.append((following, length + 1, seen | {following[2]}))
    return found


@given(protocols())
def test_every_wait_from_higher_to_lower_is_reported_with_a_real_shortest_chain(
        drawn: tuple[str, SystemConfig, list[str], list[Interaction], bool, set[Interaction]]) -> None:
    text, config, roles, steps, loop, bounded = drawn
    rank = {r: config.groups[g].priority or 0 for r in roles if (g := config.group_of(r))}
    group = {r: g for r in roles if (g := config.group_of(r))}
    report = analyse(text, config)
    expected = oracle(roles, steps, loop, bounded, rank, group)
    assert {(i.high.role, i.low.role): len(i.chain) for i in report.inversions} == expected
    for found in report.inversions:
        _check_chain(found, group, rank)


def _check_chain(found: Inversion, group: dict[str, str], rank: dict[str, int]) -> None:
    chain = found.chain
    assert chain[0].role == found.high.role and chain[-1].peer == found.low.role
    assert all(first.peer == second.role for first, second in itertools.pairwise(chain))
    assert len({w.role for w in chain} | {found.low.role}) == len(chain) + 1  # no role twice
    assert rank[found.low.role] < rank[found.high.role] and group[found.low.role] != group[found.high.role]


# ---- the chain search: polynomial, and the same chains as the exhaustive search ------------------

def exhaustive_chains(graph: nx.DiGraph[Wait], start: Wait) -> list[tuple[Wait, ...]]:
    """The first version's search, kept as the oracle: every chain from ``start`` that repeats no
    thread, shortest first, skipping a wait reached again with at least an earlier visit's threads
    (exponential in the worst case)."""
    def thread(wait: Wait) -> tuple[str, str]:
        return wait.role, wait.state[:wait.state.rfind(".") + 1]

    def together(first: tuple[str, str], second: tuple[str, str]) -> bool:
        return first[0] == second[0] and (first[1].startswith(second[1]) or second[1].startswith(first[1]))

    chains: list[tuple[Wait, ...]] = []
    visits: dict[Wait, list[frozenset[tuple[str, str]]]] = {}
    queue: deque[tuple[Wait, ...]] = deque([(start,)])
    while queue:
        chain = queue.popleft()
        chains.append(chain)
        threads = frozenset(thread(w) for w in chain)
        for following in sorted(graph.successors(chain[-1])):
            if any(together(thread(following), t) for t in threads):
                continue
            extended = threads | {thread(following)}
            if any(earlier <= extended for earlier in visits.get(following, [])):
                continue
            visits.setdefault(following, []).append(extended)
            queue.append((*chain, following))
    return chains


class ExhaustiveSearch:
    """:class:`anodize._tools.chains.ChainSearch`'s interface over :func:`exhaustive_chains`."""

    def __init__(self, graph: nx.DiGraph[Wait]) -> None:
        self.graph = graph

    def from_waits(self, starts: Iterable[Wait]) -> Chains:
        best: dict[str, tuple[Wait, ...]] = {}
        for start in starts:
            for chain in exhaustive_chains(self.graph, start):
                known = best.get(chain[-1].peer)
                if known is None or (len(chain), chain) < (len(known), known):
                    best[chain[-1].peer] = chain
        return Chains(dict(sorted(best.items())), frozenset())

    def from_role(self, role: str) -> Chains:
        return self.from_waits(w for w in self.graph.nodes if w.role == role)


@st.composite
def branching_protocols(draw: st.DrawFn) -> tuple[str, SystemConfig]:
    """One loop or sequence, or two in parallel (on distinct channels), bounded channels, external roles."""
    names = [f"R{i}" for i in range(draw(st.integers(2, 5)))]
    pair = st.tuples(st.sampled_from(names), st.sampled_from(names)).filter(lambda p: p[0] != p[1])
    parts, used = [], set[tuple[str, str]]()
    for b in range(draw(st.integers(1, 2))):
        taken = frozenset(used)  # parallel branches must not share a channel
        steps = draw(st.lists(pair.filter(lambda p, taken=taken: p not in taken), min_size=1, max_size=8))
        body = " ".join(f"{a} -> {c} : m{b}x{i}." for i, (a, c) in enumerate(steps))
        parts.append(f"mu t{b}. {body} t{b}" if draw(st.booleans()) else f"{body} end")
        used |= set(steps)
    roles = [r for r in names if any(r in p for p in used)]
    text = f"global G({', '.join(roles)}) = " + (parts[0] if len(parts) == 1 else f"( {' || '.join(parts)} )")
    external = tuple(r for r in roles if draw(st.integers(0, 5)) == 0)
    priorities = st.sampled_from([None, 10, 30, 50, 90])
    group_of = {r: draw(st.integers(0, 2)) for r in roles if r not in external}
    groups: Groups = {f"g{g}": (draw(priorities), tuple(r for r, h in group_of.items() if h == g), None)
                      for g in sorted(set(group_of.values()))}
    bounded = draw(st.sets(st.sampled_from(sorted(used))))
    return text, system(groups, external=external, capacities={f"{a}->{c}": 1 for a, c in bounded})


@settings(max_examples=150)
@given(branching_protocols())
def test_the_polynomial_search_finds_what_the_exhaustive_one_finds(drawn: tuple[str, SystemConfig]) -> None:
    text, config = drawn
    try:
        report = analyse(text, config)
    except sessiontypes.ProtocolError:
        assume(False)
        raise
    with mock.patch.object(inversion, "ChainSearch", ExhaustiveSearch):
        assert report == analyse(text, config)
    assert all(found.exact for found in report.inversions)


@st.composite
def waits_graphs(draw: st.DrawFn) -> nx.DiGraph[Wait]:
    """Random waits-for graphs, denser in paths that come back to a role than protocols are."""
    roles = [f"R{i}" for i in range(draw(st.integers(2, 4)))]
    states = st.sampled_from(["0", "1", "2", "3", "0.1.0", "0.1.1", "0.2.0"])
    waits = draw(st.lists(st.builds(lambda r, s, p: Wait(roles[r], s, roles[p], "recv", f"?{roles[p]}"),
                                    st.integers(0, len(roles) - 1), states, st.integers(0, len(roles) - 1))
                          .filter(lambda w: w.role != w.peer), min_size=1, max_size=14, unique=True))
    candidates = [(a, b) for a in waits for b in waits if b.role == a.peer]
    keep = draw(st.lists(st.booleans(), min_size=len(candidates), max_size=len(candidates)))
    graph: nx.DiGraph[Wait] = nx.DiGraph()
    graph.add_nodes_from(waits)
    graph.add_edges_from(edge for edge, kept in zip(candidates, keep, strict=True) if kept)
    return graph


@settings(max_examples=300)
@given(waits_graphs())
def test_the_shortest_chains_are_the_exhaustive_searchs(graph: nx.DiGraph[Wait]) -> None:
    search, oracle = ChainSearch(graph), ExhaustiveSearch(graph)
    for role in sorted({w.role for w in graph.nodes}):
        assert search.from_role(role) == oracle.from_role(role)
    for wait in sorted(graph.nodes):
        assert search.from_waits([wait]) == oracle.from_waits([wait])


# A: ?B(y); B: !C(p) ?C(x) !A(y) ?D(z) !C(w); C: ?B(p) !B(x) ?B(w). The shortest path from A to a wait
# on D goes A ?B(y) -> B ?C(x) -> C ?B(p) -> B ?D(z): through B twice, which cannot be: B waits on C at
# state 1, long before it waits on D. No chain from A reaches D.
THROUGH_TWICE = "global G(A, B, C, D) = B -> C : p. C -> B : x. B -> A : y. D -> B : z. B -> C : w. end"
THROUGH_TWICE_GROUPS: Groups = {"a": (90, ("A",), None), "b": (50, ("B", "C"), None), "d": (10, ("D",), None)}


def test_a_path_through_a_role_twice_is_no_chain() -> None:
    report = analyse(THROUGH_TWICE, system(THROUGH_TWICE_GROUPS))
    assert pairs(report) == [("A", "B"), ("A", "C"), ("B", "D"), ("C", "D")]
    assert all(found.exact for found in report.inversions)


def test_past_its_budget_the_search_keeps_the_shortest_path_and_says_it_may_not_happen(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(chains, "EXACT_SEARCH_WORK", 0)
    report = analyse(THROUGH_TWICE, system(THROUGH_TWICE_GROUPS))
    assert pairs(report) == [("A", "B"), ("A", "C"), ("A", "D"), ("B", "D"), ("C", "D")]
    through = report.inversions[2]
    assert [w.role for w in through.chain] == ["A", "B", "C", "B"]
    assert not through.exact and through.to_dict()["exact"] is False
    assert through.lines()[-1] == ("  note: the protocol is too large for the exact chain search; this chain "
                                   "passes through a role twice and may not be a wait that can happen")
    assert all(found.exact for found in report.inversions if found is not through)


def dense(count: int, messages: int, loop: bool, seed: int) -> tuple[str, SystemConfig]:
    """A random protocol in which every role talks to many others, one group per role."""
    rnd = random.Random(seed)
    roles = [f"R{i}" for i in range(count)]
    steps = [(roles[i], roles[(i + 1) % count]) for i in range(count)]  # every role takes part
    steps += [tuple(rnd.sample(roles, 2)) for _ in range(messages - count)]
    rnd.shuffle(steps)
    body = " ".join(f"{a} -> {b} : m{i}." for i, (a, b) in enumerate(steps))
    text = f"global G({', '.join(roles)}) = " + (f"mu t. {body} t" if loop else f"{body} end")
    return text, system({f"g{i}": (rnd.choice([None, 10, 30, 50, 70, 90]), (r,), None) for i, r in enumerate(roles)})


def test_a_large_dense_loop_is_analysed_with_the_shortest_chains() -> None:
    text, config = dense(40, 240, loop=True, seed=1)
    report = analyse(text, config)
    # in a loop every state can still reach every action: a role waits on whoever it receives from,
    # and the shortest chains are the shortest paths of that graph between roles
    receives = nx.DiGraph([(b, a) for a, b in re.findall(r"(\w+) -> (\w+) :", text)])
    rank = {r: config.groups[g].priority or 0 for r in receives if (g := config.group_of(r))}
    expected = {(high, low): length for high, lengths in nx.shortest_path_length(receives)
                for low, length in lengths.items() if rank[low] < rank[high]}
    assert {(i.high.role, i.low.role): len(i.chain) for i in report.inversions} == expected
    assert len(expected) > 500 and report.waits == 240
    assert all(found.exact for found in report.inversions)


def test_a_large_dense_sequence_is_analysed_with_chains_that_repeat_no_role() -> None:
    text, config = dense(40, 160, loop=False, seed=2)
    report = analyse(text, config)
    assert len(report.inversions) > 300
    roles = [f"R{i}" for i in range(40)]
    rank = {r: config.groups[g].priority or 0 for r in roles if (g := config.group_of(r))}
    for found in report.inversions:
        assert found.exact
        _check_chain(found, {r: config.group_of(r) or "" for r in rank}, rank)


# ---- the command ---------------------------------------------------------------------------------

def test_the_lint_command_prints_the_inversions_after_the_isolation_findings_as_warnings(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)
    (tmp_path / "ask.proto").write_text(ASK_REPLY + "\n", encoding="utf-8")
    fixtures = REPO / "tests" / "anodize" / "lint_fixtures"
    path = tmp_path / "system.toml"
    path.write_text(f'protocol = "ask.proto"\nglobal = "AskReply"\npythonpath = ["{fixtures}"]\n'
                    '[groups.control]\npriority = 90\ncpus = [0]\nroles = { H = "constants:producer" }\n'
                    '[groups.logging]\npriority = 50\nroles = { Spinner = "constants:producer" }\n'
                    '[groups.slow]\npriority = 10\ncpus = [0]\npriority_inheritance = false\n'
                    'roles = { L = "constants:consumer" }\n',
                    encoding="utf-8")
    out_json = tmp_path / "lint.json"
    assert main(["lint", str(path), "--json", str(out_json)]) == 0  # an inversion is a warning
    out, err = capsys.readouterr()
    assert err == ""
    assert out == (
        "no isolation problems found in 1 module\n"
        "\n"
        "unbounded inversion: H (group control, priority 90, CPUs 0) can wait on L (group slow, priority 10, CPUs 0)\n"
        "  chain: H ?L(reply) [state 1] -> L\n"
        "  roles: H (group control, priority 90, CPUs 0), L (group slow, priority 10, CPUs 0)\n"
        "  preempted by: logging (priority 50, CPUs any) over L\n"
        "  priority inheritance: cannot cover it: H waits on group slow, which turns it off "
        "(priority_inheritance = false)\n"
        "  unbounded: logging can preempt L for as long as it runs\n"
        "1 priority inversion (1 unbounded) among 2 waits; priority inheritance is turned off in some groups\n"
        f"wrote {out_json}\n")
    data = json.loads(out_json.read_text(encoding="utf-8"))
    assert (data["findings"], data["inheritance_applied"], data["waits"]) == ([], False, 2)
    assert data["inversions"][0]["chain"] == [
        {"role": "H", "state": "1", "peer": "L", "kind": "recv", "action": "?L(reply)"}]
    assert data["inversions"][0]["preempted_by"] == [{"group": "logging", "priority": 50, "role": "L", "cpus": None}]
    assert data["inversions"][0]["exact"] is True

    # --strict fails on the unbounded inversion, with the same output
    assert main(["lint", str(path), "--strict"]) == 1
    assert capsys.readouterr().out == out.removesuffix(f"wrote {out_json}\n")

    # keep logging off CPU 0: the inversion is bounded, a warning even with --strict
    path.write_text(path.read_text(encoding="utf-8").replace(
        "[groups.logging]\npriority = 50\n", "[groups.logging]\npriority = 50\ncpus = [1]\n"), encoding="utf-8")
    assert main(["lint", str(path), "--strict"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[2].startswith("bounded inversion: H")
    assert out.endswith("1 priority inversion (0 unbounded) among 2 waits; "
                        "priority inheritance is turned off in some groups\n")


TINMAN_INVERSIONS = [
    ("Move", "Camera", ["Move", "VisOdom", "Camera"]),
    ("Move", "VisOdom", ["Move", "VisOdom"]),
    ("Move", "Planner", ["Move", "Planner"]),
    ("Move", "Gazebo", ["Move", "Gazebo"]),  # the scan branch, not the control loop
    ("Camera", "Gazebo", ["Camera", "Gazebo"]),
    ("VisOdom", "Gazebo", ["VisOdom", "Gazebo"]),  # the wheel odometry's branch
]


def test_lint_tinman_by_name_prints_its_inversions(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)
    assert main(["lint", "tinman"]) == 1  # its isolation findings fail the lint; the inversions are warnings
    out = capsys.readouterr().out
    analysis = out.split("\n\n", 1)[1]
    blocks = [line for line in analysis.splitlines() if "inversion:" in line]
    assert [b.split(": ", 1)[1].split(" (")[0] for b in blocks] == [h for h, _, _ in TINMAN_INVERSIONS]
    chains = [line for line in analysis.splitlines() if line.startswith("  chain: ")]
    assert [[part.split()[0] for part in c[len("  chain: "):].split(" -> ")] for c in chains] == [
        r for _, _, r in TINMAN_INVERSIONS]
    assert "  preempted by: perception (priority 50, CPUs any) over Planner" in analysis
    # Every group a control role waits on takes no boosts (decision 0065 for planning): no chain is
    # bounded by inheritance, and each says which group turned it off.
    unbounded = [line for line in blocks if line.startswith("unbounded inversion:")]
    assert len(unbounded) == 6
    assert ("  priority inheritance: cannot cover it: Move waits on group planning, which turns it off "
            "(priority_inheritance = false)") in analysis
    assert "Gazebo (group simulation, no priority (normal scheduling, nice -10), CPUs any)" in analysis
    assert "  chain: Move ?Gazebo(LaserScan) [state 0.2.0] -> Gazebo" in analysis  # never state 0.1.x: control
    assert analysis.endswith("6 priority inversions (6 unbounded) among 14 waits; "
                             "priority inheritance is turned off in some groups\n")


def test_lint_tinman_exits_0_on_its_inversions_alone_and_1_with_strict(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)
    monkeypatch.setattr("anodize._tools.lint.lint_report", lambda config: LintReport((), ("tinman/app.py",)))
    assert main(["lint", "tinman"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("no isolation problems found in 1 module\n\nunbounded inversion: Move")
    assert main(["lint", "tinman", "--strict"]) == 1  # the waits on the simulated world are unbounded
    assert capsys.readouterr().out == out


def test_the_guide_shows_tinmans_real_inversion_analysis(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)
    main(["lint", "tinman"])
    analysis = capsys.readouterr().out.split("\n\n", 1)[1]
    guide = (REPO / "docs" / "guide" / "inversion.md").read_text(encoding="utf-8")
    shown = guide.split("$ anodize lint tinman\n", 1)[1].split("```", 1)[0]
    assert shown.split("\n\n", 1)[1] == analysis


def test_a_named_system_without_a_system_file_is_a_usage_error(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("anodize._tools.cli._named_systems", lambda: ["demo"])
    monkeypatch.setattr("anodize._tools.named.find_named", lambda name: object())
    assert main(["lint", "demo"]) == 2
    assert capsys.readouterr().err == (
        "anodize lint: error: named system demo has no system file to lint (it declares no system_file)\n")
