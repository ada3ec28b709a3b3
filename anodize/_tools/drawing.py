"""Pictures of communication graphs (PNG/SVG) with matplotlib (the ``graph`` extra)."""

from __future__ import annotations

import math
from pathlib import Path

import networkx as nx

from .._extras import import_extra


def draw_communication_graph(graph: nx.DiGraph[str], path: Path) -> None:
    """Draw roles on a circle, one labelled arrow per channel, and save to ``path``.

    The format follows the suffix (``.png`` or ``.svg``).
    """
    matplotlib = import_extra("matplotlib", "graph", "drawing a communication graph (.png/.svg)")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    roles = list(graph.nodes)
    count = max(len(roles), 1)
    size = 4 + 1.2 * math.sqrt(count) * 2
    fig, ax = plt.subplots(figsize=(size, size * 0.8), dpi=120)
    positions = nx.circular_layout(graph) if count > 2 else nx.spring_layout(graph, seed=1)
    bidirectional = {(a, b) for a, b in graph.edges if graph.has_edge(b, a)}
    for sender, receiver, data in graph.edges(data=True):
        bend = 0.18 if (sender, receiver) in bidirectional else 0.06
        nx.draw_networkx_edges(graph, positions, edgelist=[(sender, receiver)], ax=ax,
                               arrowstyle="-|>", arrowsize=18, width=1.4, edge_color="#445",
                               connectionstyle=f"arc3,rad={bend}", node_size=3400)
        (x1, y1), (x2, y2) = positions[sender], positions[receiver]
        # label near the middle of the arc, pushed to the arc's side
        mx, my = (x1 + x2) / 2, (y1 + y2) / 2
        nx_, ny_ = (y1 - y2), (x2 - x1)
        norm = math.hypot(nx_, ny_) or 1.0
        offset = bend * 0.5 * math.hypot(x2 - x1, y2 - y1)
        ax.text(mx - nx_ / norm * offset, my - ny_ / norm * offset, "\n".join(data["messages"]),
                fontsize=9, ha="center", va="center", color="#123",
                bbox={"boxstyle": "round,pad=0.2", "fc": "#fffbe6", "ec": "#cc9", "lw": 0.6})
    nx.draw_networkx_nodes(graph, positions, ax=ax, node_size=3400, node_color="#dde8f7",
                           edgecolors="#2a4d7f", linewidths=1.5, node_shape="o")
    nx.draw_networkx_labels(graph, positions, ax=ax, font_size=9, font_weight="bold")
    ax.set_title(f"global {graph.name}: communication graph", fontsize=12)
    ax.margins(0.18)
    ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
