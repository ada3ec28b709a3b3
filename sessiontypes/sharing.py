"""Nodes shared between places in a module's types, and the memo tables keyed on them.

Resolution returns one node for every use of a declaration
(:mod:`sessiontypes.expand`), so a module's types form a DAG whose unfolding
as a tree can be exponentially larger than the file. A pass that folds a
type (collects roles or channels, checks parallel branches, projects) stays
linear by remembering its result for the nodes that occur in more than one
place; every other node is reached once per walk anyway.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any, TypeVar

__all__ = ["Sharing", "find_shared"]

Node = TypeVar("Node")


class Sharing:
    """The shared nodes of one module's types, and per-pass results for them.

    Results are keyed by ``id``; the nodes are held here so that an id cannot
    be reused by another object while the tables exist.

    Args:
        nodes: the shared nodes by id; a live view (resolution adds to it as
            it goes, and passes run between resolutions).
    """

    def __init__(self, nodes: Mapping[int, object] | None = None) -> None:
        # Passes test ``id(node) in sharing.nodes``: no method call on the hot path.
        self.nodes: Mapping[int, object] = nodes if nodes is not None else {}
        self._tables: dict[object, dict[int, tuple[object, Any]]] = {}

    def get(self, table: object, node: object) -> Any | None:
        """The result remembered for ``node`` in ``table``, or None."""
        found = self._tables.get(table, {}).get(id(node))
        if found is None or found[0] is not node:
            return None
        return found[1]

    def table(self, table: object) -> dict[int, tuple[Any, Any]]:
        """The whole table ``table``: (node, result) by the node's id, to read and fill in a loop."""
        return self._tables.setdefault(table, {})

    def put(self, table: object, node: object, result: object) -> None:
        """Remember ``result`` for ``node`` in ``table`` (a pass's name and parameters)."""
        self._tables.setdefault(table, {})[id(node)] = (node, result)


def find_shared(root: Node, children: Callable[[Node], Iterable[Node]]) -> dict[int, Node]:
    """The nodes reachable from ``root`` along more than one path, by id (one walk)."""
    seen: set[int] = set()
    shared: dict[int, Node] = {}
    stack = [root]
    while stack:  # iterative: sequences nest deeply
        node = stack.pop()
        if id(node) in seen:
            shared[id(node)] = node
            continue
        seen.add(id(node))
        stack.extend(children(node))
    return shared
