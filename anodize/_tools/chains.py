"""The shortest chains of waits from a role, in polynomial time.

A *chain* is a path in the waits-for graph (:mod:`.waits`): A waits on B, which waits
on C, ... A chain never has two waits of one *thread* (a role, or one parallel branch
of it): a thread is in one state at a time, so it cannot wait twice on one chain.

:class:`ChainSearch` answers, for a set of starting waits, the shortest chain (ties
broken by the waits' order) to every peer they can end up waiting on. Finding the
shortest path that avoids repeating a thread is hard in general (paths that avoid
forbidden pairs), so it works in two steps:

1. A breadth-first search over the graph, ignoring threads: polynomial, and its shortest
   path is the answer whenever it repeats no thread. It always does in a loop without
   choices (there, a role's every state can still reach its every action, so a path
   back to a role has a shortcut) and in most protocols.
2. Only for the peers whose shortest path repeats a thread: a breadth-first search over
   chains that avoid it, which skips a wait reached again with at least the threads of
   an earlier visit. It is exact but can grow exponentially, so it stops after
   :data:`EXACT_SEARCH_WORK` steps; a peer it has not reached by then keeps the path of
   step 1, marked inexact (an over-approximation: it may be a wait that cannot happen).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

import networkx as nx

from .waits import Wait

__all__ = ["EXACT_SEARCH_WORK", "ChainSearch", "Chains"]

# Steps (a chain followed one wait further, or compared with an earlier visit) the exact
# search may take per call. Every protocol of the tests and TinMan needs a few hundred at most.
EXACT_SEARCH_WORK = 20_000

Chain = tuple[Wait, ...]
Thread = tuple[str, str]
_Path = tuple[int, ...]  # waits by their index in the waits' order: compared fast, in the same order


@dataclass(frozen=True)
class Chains:
    """The shortest chains from some starting waits.

    Attributes:
        shortest: peer -> the shortest chain (then the first in the waits' order) from a
            starting wait to a wait on that peer.
        inexact: the peers whose chain the exact search did not reach within its budget:
            theirs is the shortest path, which passes through some thread twice.
    """

    shortest: dict[str, Chain]
    inexact: frozenset[str]


class ChainSearch:
    """The shortest chains of one waits-for graph (:func:`.waits.waits_for_graph`).

    Each set of starting waits is searched once; the answers are kept.
    """

    def __init__(self, graph: nx.DiGraph[Wait]) -> None:
        self._waits = sorted(graph.nodes)
        index = {wait: i for i, wait in enumerate(self._waits)}
        self._successors = [sorted(index[w] for w in graph.successors(wait)) for wait in self._waits]
        self._threads = [_thread(wait) for wait in self._waits]
        self._index = index
        self._cache: dict[tuple[Wait, ...], Chains] = {}

    def from_waits(self, starts: Iterable[Wait]) -> Chains:
        """The shortest chain from any of ``starts`` to every peer a chain can end on."""
        roots = tuple(sorted(starts))
        if roots not in self._cache:
            self._cache[roots] = self._search([self._index[root] for root in roots])
        return self._cache[roots]

    def from_role(self, role: str) -> Chains:
        """The shortest chains from any wait of ``role``."""
        return self.from_waits(wait for wait in self._waits if wait.role == role)

    def _search(self, roots: list[int]) -> Chains:
        paths = self._shortest_paths(roots)
        repeating = {peer for peer, path in paths.items() if not self._one_thread_each(path)}
        exact: dict[str, _Path] = {}
        finished = True
        if repeating:
            exact, finished = self._exact_chains(roots)
        shortest = {peer: path for peer, path in paths.items() if peer not in repeating}
        shortest.update(exact)
        inexact = set()
        if not finished:  # a peer not reached yet may still have a chain: keep its path, say so
            for peer in repeating - exact.keys():
                shortest[peer] = paths[peer]
                inexact.add(peer)
        return Chains({peer: tuple(self._waits[i] for i in path) for peer, path in sorted(shortest.items())},
                      frozenset(inexact))

    def _shortest_paths(self, roots: list[int]) -> dict[str, _Path]:
        """peer -> the shortest path to a wait on it, the first in the waits' order.

        Breadth-first, roots and successors in order, first visit wins: each wait's recorded
        path is then its shortest and, among those, the first (a path's order is its
        prefix's, and prefixes are met in order). A path does not enter the roots' threads
        again: no chain can, and a root's own role gets there shorter from that root.
        """
        closed = [self._threads[root] for root in roots]
        path: dict[int, _Path] = {root: (root,) for root in roots}
        queue = deque(roots)
        while queue:
            wait = queue.popleft()
            for following in self._successors[wait]:
                if following not in path and not any(_together(self._threads[following], t) for t in closed):
                    path[following] = (*path[wait], following)
                    queue.append(following)
        best: dict[str, _Path] = {}
        for wait, found in path.items():
            peer = self._waits[wait].peer
            known = best.get(peer)
            if known is None or (len(found), found) < (len(known), known):
                best[peer] = found
        return best

    def _exact_chains(self, roots: list[int]) -> tuple[dict[str, _Path], bool]:
        """peer -> the shortest chain that repeats no thread, and whether the search finished.

        Chains are taken shortest first, then in the waits' order, so the first chain that
        ends on a peer is its answer even if the search stops early.
        """
        found: dict[str, _Path] = {}
        visits: dict[int, list[frozenset[Thread]]] = {root: [frozenset({self._threads[root]})] for root in roots}
        queue: deque[tuple[_Path, frozenset[Thread]]] = deque(((root,), visits[root][0]) for root in roots)
        work = 0
        while queue:
            chain, threads = queue.popleft()
            found.setdefault(self._waits[chain[-1]].peer, chain)
            for following in self._successors[chain[-1]]:
                earlier = visits.setdefault(following, [])
                work += 1 + len(earlier)
                if work > EXACT_SEARCH_WORK:
                    return found, False
                thread = self._threads[following]
                if any(_together(thread, t) for t in threads):
                    continue
                extended = threads | {thread}
                # reached before with fewer threads: everything from here was open to that visit too
                if any(visit <= extended for visit in earlier):
                    continue
                earlier.append(extended)
                queue.append(((*chain, following), extended))
        return found, True

    def _one_thread_each(self, path: _Path) -> bool:
        threads = [self._threads[wait] for wait in path]
        return not any(_together(first, second)
                       for i, first in enumerate(threads) for second in threads[i + 1:])


def _thread(wait: Wait) -> Thread:
    """The role and the branch of it a wait is in: ``("Move", "0.2.")`` for state ``0.2.0``."""
    return wait.role, wait.state[:wait.state.rfind(".") + 1]


def _together(first: Thread, second: Thread) -> bool:
    """Whether two waits are of one thread: one role, in one branch or one enclosing the other."""
    return first[0] == second[0] and (first[1].startswith(second[1]) or second[1].startswith(first[1]))
