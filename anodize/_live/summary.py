"""A message as plain data for a terminal (``anodize echo``): fields kept, arrays summarized.

As ``ros2 topic echo`` shows a message, field by field, but an array (an image's pixels,
a scan's ranges) longer than :data:`ARRAY_ITEMS` is shown as its shape, type and range
rather than thousands of numbers, and a long string or list is cut.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

__all__ = ["summarize", "ARRAY_ITEMS", "TEXT_CHARS"]

ARRAY_ITEMS = 16   # items of an array or list shown whole; a longer one is summarized
TEXT_CHARS = 200   # characters of a string shown
_DEPTH = 12        # nesting shown; deeper is elided


def summarize(value: object, depth: int = 0) -> Any:
    """``value`` as JSON-ready data: dataclasses (and ROS messages) as dicts of their fields,
    numpy arrays and long sequences summarized as one string."""
    if depth > _DEPTH:
        return "..."
    if value is None or isinstance(value, bool | int | str):
        return value if not isinstance(value, str) or len(value) <= TEXT_CHARS else value[:TEXT_CHARS] + "..."
    if isinstance(value, float):
        return value if math.isfinite(value) else repr(value)
    if isinstance(value, bytes | bytearray | memoryview):
        return f"<{len(value)} bytes>"
    shape = getattr(value, "shape", None)
    if shape is not None and hasattr(value, "dtype") and hasattr(value, "tolist"):
        return _array(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: summarize(getattr(value, f.name, None), depth + 1) for f in dataclasses.fields(value)
                if not f.name.startswith("_")}
    if isinstance(value, dict):
        return {str(k): summarize(v, depth + 1) for k, v in list(value.items())[:ARRAY_ITEMS]}
    if isinstance(value, list | tuple | set | frozenset):
        items = list(value)
        if len(items) > ARRAY_ITEMS:
            return f"<{len(items)} items: {', '.join(repr(x) for x in items[:3])}, ...>"
        return [summarize(x, depth + 1) for x in items]
    return repr(value)[:TEXT_CHARS]


def _array(value: Any) -> Any:
    if value.size <= ARRAY_ITEMS and value.ndim <= 1:
        return [summarize(x) for x in value.tolist()]
    text = f"<array {'x'.join(str(n) for n in value.shape)} {value.dtype}"
    if value.size and value.dtype.kind in "iufb":
        low, high = value.min(), value.max()
        text += f" min {low.item()!r} max {high.item()!r}"
    return text + ">"
