"""ROS names: namespaces and remaps, as ``ros2 launch`` applies them to a node's topics.

A topic name written without a leading ``/`` (``cmd_vel``) is relative: it is resolved
in the namespace of the group whose role publishes it (``[groups.x] namespace``), which
is itself resolved in the system's (``[ros] namespace``): ``/r1`` + ``cmd_vel`` is
``/r1/cmd_vel``. An absolute name (``/tf``) stays as written, as in ROS. Then the
remaps (``"/cmd_vel" = "/r1/cmd_vel"``, or ``-r /cmd_vel:=/r1/cmd_vel``) rename the
resolved names; their two sides are resolved in the system's namespace first.
"""

from __future__ import annotations

from collections.abc import Mapping

from .._transport.ros_lanes import check_topic_name
from ..errors import ConfigurationError

__all__ = ["check_namespace", "check_relative_name", "resolve_name", "join_namespaces", "resolve_topics"]


def check_namespace(namespace: object) -> str | None:
    """Why ``namespace`` is not a ROS namespace (``""``, ``/r1``, or relative ``planning/arm``), or None."""
    if not isinstance(namespace, str):
        return f"expected a ROS namespace such as \"/robot1\", got {namespace!r}"
    if namespace in ("", "/"):
        return None
    problem = check_topic_name(namespace if namespace.startswith("/") else "/" + namespace)
    if problem is None:
        return None
    return problem.replace("an absolute ROS topic name", "a ROS namespace").replace('"/cmd_vel"', '"/robot1"')


def check_relative_name(name: object) -> str | None:
    """Why ``name`` is not a ROS topic name (absolute ``/cmd_vel`` or relative ``cmd_vel``), or None."""
    if not isinstance(name, str) or not name:
        return "expected a ROS topic name such as \"/cmd_vel\" or \"cmd_vel\""
    problem = check_topic_name(name if name.startswith("/") else "/" + name)
    if problem is None:
        return None
    return problem.replace("an absolute ROS topic name", "a ROS topic name").replace(
        '"/cmd_vel"', '"/cmd_vel" or, relative to the namespace, "cmd_vel"')


def join_namespaces(outer: str, inner: str) -> str:
    """``inner`` resolved in ``outer``: an absolute ``inner`` stays, a relative one goes under ``outer``."""
    if inner.startswith("/"):
        return inner.rstrip("/")
    outer = outer.rstrip("/")
    return f"{outer}/{inner}".rstrip("/") if inner else outer


def resolve_name(name: str, namespace: str) -> str:
    """``name`` as the fully qualified topic ``namespace`` makes it (absolute names stay)."""
    if name.startswith("/"):
        return name
    return f"{namespace.rstrip('/')}/{name}" if namespace.strip("/") else f"/{name}"


def resolve_topics(topics: Mapping[str, str], namespace: str, namespace_of: Mapping[str, str],
                   remap: Mapping[str, str]) -> dict[str, str]:
    """Each topic entry's fully qualified name: namespaces applied, then remaps.

    Args:
        topics: ``"Sender->Receiver[:label]"`` -> topic name, as written.
        namespace: the system's namespace.
        namespace_of: role -> its group's namespace (relative ones go under ``namespace``);
            a topic takes its sender's, or its receiver's when the sender runs in no group.
        remap: resolved name -> new name, each side resolved in ``namespace``.

    Raises:
        ConfigurationError: a remap whose source is no topic of the system.
    """
    resolved: dict[str, str] = {}
    for key, name in topics.items():
        sender, _, rest = key.partition("->")
        receiver = rest.partition(":")[0].strip()
        group = namespace_of.get(sender.strip(), namespace_of.get(receiver, ""))
        resolved[key] = resolve_name(name, join_namespaces(namespace, group))
    rules = {resolve_name(a, namespace): resolve_name(b, namespace) for a, b in remap.items()}
    unused = sorted(set(rules) - set(resolved.values()))
    if unused:
        raise ConfigurationError(f"remap {unused[0]}: no topic of the system is named so; its topics are "
                                 f"{', '.join(sorted(set(resolved.values()))) or '(none)'}")
    return {key: rules.get(name, name) for key, name in resolved.items()}
