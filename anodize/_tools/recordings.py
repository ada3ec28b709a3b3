"""What ``anodize verify`` and ``anodize replay`` need besides the recording: the protocol, the topic map,
the role's function.

A recording is untrusted data: the protocol it carries is read for its structure only (the
commands tell :func:`~anodize._recording.verify.verify` and :func:`~anodize._recording.replay.replay`
not to import the payload classes it names), and the role functions it names are shown, never
imported: the function to replay is always the user's (``--function``).
"""

from __future__ import annotations

import sys
import tomllib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import sessiontypes
from sessiontypes import GlobalType
from sessiontypes.limits import PROTOCOL, SYSTEM_FILE, check_text, read_limited

from .._recording.metadata import recorded_protocol, role_functions
from .._recording.reader import Recording
from .._supervision.group import resolve_function
from .._supervision.rosnames import check_namespace, check_relative_name, resolve_topics
from .._transport.ros_lanes import ros_settings
from ..errors import ConfigurationError

__all__ = ["protocol_of", "topic_map", "role_function"]


def protocol_of(recording: Recording, path: str | None, name: str | None) -> GlobalType:
    """The global type to check ``recording`` against: from ``path`` if given, else the one the
    recording carries (anodize records its protocol's source); ``name`` picks the global type.

    Raises:
        ConfigurationError: no protocol given and the recording carries none, or no such global.
        ProtocolError: the protocol does not parse or check.
    """
    info = recording.info
    recorded = recorded_protocol(recording)
    if path is not None:
        module = sessiontypes.load(path)
    elif recorded is not None:
        text, shown = recorded  # parsed and checked, bounded as a protocol file: nothing it names is imported
        module = sessiontypes.loads(check_text(text, PROTOCOL, f"{recording.path}: {shown}"), shown)
    else:
        raise ConfigurationError(f"{recording.path} was not recorded by anodize: give its protocol with "
                                 "--protocol FILE.proto (and --global G, and --topics MAP)")
    name = name or (info.get("global") if path is None else None)
    if name is None:
        if len(module.globals) != 1:
            raise ConfigurationError(f"{module.path} declares {len(module.globals)} global types: pick one with "
                                     f"--global ({', '.join(module.globals) or 'none'})")
        return next(iter(module.globals.values()))
    if name not in module.globals:
        raise ConfigurationError(f"{module.path} has no global type {name}; expected one of "
                                 f"{', '.join(module.globals) or '(none)'}")
    return module.globals[name]


def topic_map(path: str, global_type: GlobalType) -> dict[str, tuple[str, str, str]]:
    """topic -> (sender, receiver, label), from a TOML file of ``"Sender->Receiver[:label]" = "/topic"``
    entries, at its top level or in ``[ros.topics]`` (so a system file serves as it is).

    Raises:
        ConfigurationError: the file is not TOML, or an entry names no channel or label of
            ``global_type`` (naming the entry).
    """
    try:
        data = tomllib.loads(read_limited(path, SYSTEM_FILE).decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError) as error:
        raise ConfigurationError(f"{path}: not a TOML file: {error}") from None
    table = data.get("ros", {}).get("topics", data) if isinstance(data.get("ros"), dict) else data
    if not isinstance(table, dict):
        raise ConfigurationError(f"{path}: ros.topics: expected a table of \"Sender->Receiver:label\" = "
                                 f"\"/topic\" entries, got a {type(table).__name__}")
    entries = {key: value for key, value in table.items() if isinstance(value, str) and "->" in key}
    if not entries:
        raise ConfigurationError(f"{path}: no \"Sender->Receiver:label\" = \"/topic\" entries "
                                 "(at the top level or in [ros.topics])")
    machines = {role: global_type.project(role).fsm() for role in global_type.roles}
    channels = {(t.peer, role) for role, m in machines.items() for t in m.all_transitions()
                if t.action == "recv" and t.peer is not None}
    try:
        settings = ros_settings(machines, channels, _resolved(data, entries))
    except ConfigurationError as error:
        raise ConfigurationError(f"{path}: {error}") from None
    return {topic.name: key for key, topic in settings.topics.items()}


def _resolved(data: dict[str, Any], entries: dict[str, str]) -> dict[str, str]:
    """A system file's topic entries fully qualified, as the run named them: relative names in
    their groups' and the file's ``[ros] namespace``, then its ``[ros.remap]``.

    Raises:
        ConfigurationError: a namespace or remap that is not a ROS name, or a remap of no topic.
    """
    ros: dict[str, Any] = data["ros"] if isinstance(data.get("ros"), dict) else {}
    groups: dict[str, Any] = data["groups"] if isinstance(data.get("groups"), dict) else {}
    namespace_of = {role: group.get("namespace", "") for group in groups.values() if isinstance(group, dict)
                    and isinstance(group.get("roles"), dict) for role in group["roles"]}
    remap: dict[Any, Any] = ros["remap"] if isinstance(ros.get("remap"), dict) else {}
    namespace = ros.get("namespace", "")
    for given in (namespace, *namespace_of.values()):  # checked as the run checks them: never a traceback
        problem = check_namespace(given)
        if problem is not None:
            raise ConfigurationError(f"namespace {given!r}: {problem}")
    for name in (*remap, *remap.values()):
        problem = check_relative_name(name)
        if problem is not None:
            raise ConfigurationError(f"[ros.remap] {name!r}: {problem}")
    return resolve_topics(entries, namespace, namespace_of, remap)


def role_function(recording: Recording, role: str, reference: str | None,
                  pythonpath: Sequence[str] = ()) -> Callable[..., Any]:
    """The function to replay ``role`` with: ``reference`` (``"module:function"``), the user's own.
    The folders of ``pythonpath`` go to the front of ``sys.path`` first.

    A recording names the function each role ran (``role_functions``); that name is only shown,
    in the error when no reference is given: importing it would run code a file chose.

    Raises:
        ConfigurationError: no reference given (naming the function the recording says ran).
        RecordingError: (no reference given) the recording's ``role_functions`` is malformed.
        AnodizeError: the function cannot be imported.
    """
    if reference is None:
        named = role_functions(recording).get(role)
        said = (f"the recording says role {role} ran `{named}`: pass --function {named} to replay it" if named
                else f"the recording names no function for role {role}")
        raise ConfigurationError(f"replaying role {role} needs --function module:function (code of your own: what "
                                 f"a recording names is never imported); {said}")
    for folder in reversed(pythonpath):
        path = str(Path(folder).resolve())
        if path not in sys.path:
            sys.path.insert(0, path)
    return resolve_function(reference)
