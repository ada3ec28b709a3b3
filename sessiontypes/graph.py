"""The communication graph of a global type: who sends what to whom.

Roles are nodes; each ordered pair of roles that the global type connects is
one edge, labelled with the messages it carries in order of first occurrence.
This is also the set of channels a runtime needs: no edge, no channel.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from . import global_types as g
from .declarations import GlobalType
from .dot import to_dot
from .sorts import print_message

if TYPE_CHECKING:
    import networkx as nx

__all__ = ["communication_graph", "graph_to_dot"]


def communication_graph(global_type: GlobalType) -> nx.DiGraph[str]:
    """Return a ``networkx.DiGraph``: nodes are roles, edges carry ``messages`` (a list)."""
    import networkx as nx  # here, not at import: a tenth of a second that every group process paid

    graph: nx.DiGraph[str] = nx.DiGraph(name=global_type.name)
    graph.add_nodes_from(global_type.roles)
    stack: list[g.GlobalTerm] = [global_type.body]
    while stack:  # iterative: long sequences nest deeply
        term = stack.pop()
        match term:
            case g.Choice(sender=sender, receiver=receiver, branches=branches):
                if not graph.has_edge(sender, receiver):
                    graph.add_edge(sender, receiver, messages=[])
                messages: list[str] = graph.edges[sender, receiver]["messages"]
                for branch in branches:
                    text = print_message(branch.message)
                    if text not in messages:
                        messages.append(text)
                stack.extend(b.continuation for b in reversed(branches))
            case g.Routed(sender=sender, branches=routes):
                for route in routes:
                    if not graph.has_edge(sender, route.receiver):
                        graph.add_edge(sender, route.receiver, messages=[])
                    carried: list[str] = graph.edges[sender, route.receiver]["messages"]
                    if (text := print_message(route.message)) not in carried:
                        carried.append(text)
                stack.extend(r.continuation for r in reversed(routes))
            case g.Rec(body=body):
                stack.append(body)
            case g.Parallel(branches=parts):
                stack.extend(reversed(parts))
    return graph


def graph_to_dot(graph: nx.DiGraph[str]) -> str:
    """Graphviz DOT text for a communication graph."""
    import networkx as nx

    styled: Any = nx.DiGraph()
    for node in graph.nodes:
        styled.add_node(node, shape="box", style="rounded")
    for sender, receiver, data in graph.edges(data=True):
        styled.add_edge(sender, receiver, label=", ".join(data["messages"]))
    return to_dot(styled, graph.name)
