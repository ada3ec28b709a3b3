"""Graphviz DOT text for networkx graphs (deterministic, no extra dependency)."""

from __future__ import annotations

from typing import Any

__all__ = ["to_dot"]


def _quote(value: object) -> str:
    text = str(value).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
    return f'"{text}"'


def _attributes(data: dict[str, Any]) -> str:
    shown = {k: v for k, v in data.items() if v is not None and not k.startswith("_")}
    if not shown:
        return ""
    return " [" + ", ".join(f"{k}={_quote(v)}" for k, v in shown.items()) + "]"


def to_dot(graph: Any, name: str, graph_attributes: dict[str, str] | None = None) -> str:
    """DOT text for a networkx (Multi)DiGraph; node and edge data become attributes."""
    lines = [f"digraph {_quote(name)} {{"]
    for key, value in (graph_attributes or {}).items():
        lines.append(f"  {key}={_quote(value)};")
    for node, data in graph.nodes(data=True):
        lines.append(f"  {_quote(node)}{_attributes(data)};")
    for source, target, data in graph.edges(data=True):
        lines.append(f"  {_quote(source)} -> {_quote(target)}{_attributes(data)};")
    lines.append("}")
    return "\n".join(lines)
