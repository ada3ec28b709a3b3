"""The ``anodize`` metadata record of a recording, read as untrusted data.

A recording may come from anywhere: each key the readers use is checked when it is read,
and one that is not what anodize writes is a :class:`~.reader.RecordingError` naming the
key, what was expected and what was found. Nothing here imports or calls what a value
names: ``role_functions`` is text to show, never code to load.
"""

from __future__ import annotations

import json
import re

from .reader import Recording, RecordingError

__all__ = ["role_functions", "group_of", "recorded_channels", "recorded_protocol", "left_out_by"]

_REFERENCE = re.compile(r"[A-Za-z_][\w.]*:[A-Za-z_][\w.]*")  # module:function, as anodize writes it
_SHOWN = 60  # characters of a malformed value shown in an error


def role_functions(recording: Recording) -> dict[str, str]:
    """role -> ``"module:function"`` the recorded run ran it with (empty when not recorded).

    Raises:
        RecordingError: the key is not a JSON object of role -> ``"module:function"``.
    """
    return _string_map(recording, "role_functions", 'role -> "module:function"', _REFERENCE)


def group_of(recording: Recording) -> dict[str, str]:
    """role -> the group it ran in (empty when not recorded).

    Raises:
        RecordingError: the key is not a JSON object of role -> group name.
    """
    return _string_map(recording, "group_of", "role -> group name", None)


def recorded_channels(recording: Recording) -> set[tuple[str, str]] | None:
    """The channels an anodize recording records (None: it does not say, e.g. a foreign bag).

    Raises:
        RecordingError: the key is not ``"Sender->Receiver"`` items separated by spaces.
    """
    text = recording.info.get("recorded_channels")
    if text is None:
        return None
    found: set[tuple[str, str]] = set()
    for item in text.split():
        sender, arrow, receiver = item.partition("->")
        if not arrow or not sender or not receiver or "->" in receiver:
            raise _error(recording, "recorded_channels", 'channels "Sender->Receiver" separated by spaces',
                         _short(item))
        found.add((sender, receiver))
    return found


def left_out_by(recording: Recording) -> str:
    """Why an anodize recording leaves channels out, in words, from its ``record_selection``
    (:meth:`~.selection.RecordSelection.to_json`): ``"recorded between groups only"``,
    ``"left out: A->B"``, ... Empty for a recording that does not say (one made before
    recordings said so, which recorded between groups only).

    Raises:
        RecordingError: the key is not a JSON object as anodize writes it.
    """
    text = recording.info.get("record_selection")
    if text is None:
        return ""
    expected = 'a JSON object {"inside": true|false, "channels": [...]|null, "exclude": [...]}'
    try:
        value = json.loads(text)
    except (ValueError, RecursionError):
        raise _error(recording, "record_selection", expected, "text that is not JSON") from None
    if not isinstance(value, dict):
        raise _error(recording, "record_selection", expected, f"a JSON {_json_kind(value)}")
    inside, channels, exclude = value.get("inside"), value.get("channels"), value.get("exclude")
    if (not isinstance(inside, bool) or not _names(exclude)
            or not (channels is None or _names(channels))):
        raise _error(recording, "record_selection", expected, _short(text))
    why = ["only the channels chosen were recorded" if channels is not None else
           "recorded between groups only: both ends in one group" if not inside else ""]
    if exclude:
        why.append("left out: " + ", ".join(str(name) for name in exclude))
    return "; ".join(part for part in why if part)


def _names(value: object) -> bool:
    return isinstance(value, list) and all(isinstance(item, str) and len(item) <= 200 for item in value)


def recorded_protocol(recording: Recording) -> tuple[str, str] | None:
    """The protocol's source and the file it was read from (None: the recording carries none)."""
    source = recording.info.get("protocol_source")
    if not source:
        return None
    return source, recording.info.get("protocol_file") or "<recorded protocol>"


def _string_map(recording: Recording, key: str, what: str, form: re.Pattern[str] | None) -> dict[str, str]:
    expected = f"a JSON object of {what}"
    text = recording.info.get(key)
    if text is None:
        return {}
    try:
        value = json.loads(text)
    except (ValueError, RecursionError):
        raise _error(recording, key, expected, "text that is not JSON") from None
    if not isinstance(value, dict):
        raise _error(recording, key, expected, f"a JSON {_json_kind(value)}")
    for name, item in value.items():
        if not isinstance(item, str) or (form is not None and form.fullmatch(item) is None):
            raise _error(recording, key, expected, f"{_short(item)} for role {_role(name)}")
    return value


def _error(recording: Recording, key: str, expected: str, found: str) -> RecordingError:
    return RecordingError(f"{recording.path}: metadata {key}: expected {expected}; found {found}")


def _json_kind(value: object) -> str:
    if isinstance(value, list):
        return "array"
    if isinstance(value, str):
        return "string"
    if isinstance(value, bool):
        return "boolean"
    return "null" if value is None else "number"


def _role(name: str) -> str:
    return name if name.isidentifier() and len(name) <= _SHOWN else _short(name)


def _short(value: object) -> str:
    text = json.dumps(value) if value is None or isinstance(value, (bool, int, float)) else repr(value)
    return text if len(text) <= _SHOWN else f"{text[:_SHOWN - 3]}..."
