"""Is a payload the one a recording holds? How ``anodize replay`` compares a sent message.

- a ROS 2 message (a channel recorded as CDR) is the same when it serializes to the same
  CDR bytes as the recorded message: bytes, not floats, so ``nan`` equals ``nan`` and
  ``0.0`` differs from ``-0.0``, exactly as a subscriber would see it;
- any other payload (recorded as JSON, :mod:`.encoding`) is written as the recording
  writes it and read back, then compared by value with the recorded one: containers item
  by item (tuples stay tuples, a dict's order does not matter), floats by ``==`` with
  ``nan`` equal to ``nan``, numpy arrays by dtype, shape and ``array_equal``, dataclasses
  field by field, objects that are neither by their class name and ``repr``.
"""

from __future__ import annotations

import dataclasses
import json
import math

from .._ros import ros_type
from .encoding import JSON_TYPE, SortCodec, from_json, to_json
from .plan import META
from .reader import RecordedTopic

__all__ = ["TopicCodecs", "payload_difference", "same_value", "short"]


class TopicCodecs:
    """The decoder of each recorded topic's messages, made once per type."""

    def __init__(self) -> None:
        self._found: dict[tuple[str, bool], SortCodec] = {}

    def codec(self, topic: RecordedTopic) -> SortCodec:
        """How ``topic``'s messages were written: CDR of its type, or JSON in a String.

        Raises:
            AnodizeError: rosbags does not know the topic's type.
        """
        as_json = topic.type_name == JSON_TYPE and topic.metadata.get(f"{META}.encoding", "json") == "json"
        key = (topic.type_name, as_json)
        found = self._found.get(key)
        if found is None:
            found = self._found[key] = SortCodec(None, ros_type(topic.type_name), json=as_json)
        return found


def payload_difference(codec: SortCodec, recorded: bytes, payload: object) -> str:
    """Why ``payload`` is not the payload recorded as ``recorded`` ("" when it is)."""
    if not codec.json:
        try:
            data = codec.encode(payload)
        except Exception as error:  # rosbags raises several kinds for a value of the wrong shape
            return f"it does not serialize as a {codec.type_name}: {type(error).__name__}: {error}"
        if data == recorded:
            return ""
        first = next((i for i, (a, b) in enumerate(zip(data, recorded, strict=False)) if a != b),
                     min(len(data), len(recorded)))
        return (f"its CDR bytes differ from the recorded ones from byte {first} on "
                f"({len(data)} bytes sent, {len(recorded)} recorded)")
    expected = codec.decode(recorded)
    actual = from_json(json.loads(json.dumps(to_json(payload), allow_nan=False)))
    return "" if same_value(expected, actual) else "the payload differs"


def same_value(a: object, b: object) -> bool:
    """Whether two values read back from a recording's JSON are equal (see the module docstring)."""
    if type(a) is not type(b):
        return False
    if type(a).__module__ == "numpy":
        import numpy as np

        assert isinstance(a, np.ndarray) and isinstance(b, np.ndarray)
        return (a.dtype == b.dtype and a.shape == b.shape
                and bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")))
    if isinstance(a, float):
        assert isinstance(b, float)
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple))
        return len(a) == len(b) and all(same_value(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict):
        assert isinstance(b, dict)
        return a.keys() == b.keys() and all(same_value(value, b[key]) for key, value in a.items())
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return all(same_value(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    return a == b


def short(value: object, limit: int = 80) -> str:
    """``repr(value)``, cut in the middle when it is longer than ``limit``."""
    text = repr(value)
    if len(text) <= limit:
        return text
    keep = (limit - 5) // 2
    return f"{text[:keep]} ... {text[-keep:]}"
