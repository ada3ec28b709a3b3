"""Decoding runs of small frames, the receiver's hot loop, compiled when it can be (and the
sender's twin, :data:`SmallFrameWriter`).

:func:`decode_run_python` is the reference; ``_frames.c`` is the same loop in C, built at
install when a C compiler and Python's headers are there (``pyproject.toml``, an optional
extension). :func:`decode_run` is the compiled loop when it was built and the environment
does not set ``ANODIZE_PURE_PYTHON`` (to anything but empty or ``0``), the reference
otherwise; :data:`COMPILED` says which. Both take the same frames and leave the same ones:
tests/anodize/test_frames.py compares them on arbitrary bytes.
"""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Callable

from .._session import compiled

__all__ = ["COMPILED", "SmallFrameWriter", "decode_run", "decode_run_python"]

# The codec's constants (codec.py; a test checks they agree): frame kind and payload tags.
_MESSAGE = 0x4D  # FrameKind.MESSAGE
_NONE, _INT = 0, 3  # Tag.NONE, Tag.INT
_U32 = struct.Struct("<I")
_I64 = struct.Struct("<q")

DecodeRun = Callable[[bytearray, int, dict[bytes, str], deque[tuple[object, int]]], int]


def decode_run_python(buffer: bytearray, at: int, names: dict[bytes, str],
                      into: deque[tuple[object, int]]) -> int:
    """Append ``((label, payload), frame size)`` to ``into`` for each complete message frame
    from ``at`` on whose label is in ``names`` and whose payload is None or an 8-byte int;
    stop at the first other or incomplete frame. Returns the offset after the last taken.

    Raises:
        ValueError: ``at`` is negative.
    """
    if at < 0:
        raise ValueError("decode_run(): the offset must not be negative")
    size = len(buffer)
    unpack_u32, unpack_int = _U32.unpack_from, _I64.unpack_from
    while size - at >= 4:
        (length,) = unpack_u32(buffer, at)
        end = at + 4 + length
        if end > size or length < 6 or buffer[at + 4] != _MESSAGE:  # 6: kind, label size, tag
            break
        (label_length,) = unpack_u32(buffer, at + 5)
        start = at + 9 + label_length
        if start > end:  # the label runs past the frame: decode_body reports it
            break
        label = names.get(bytes(buffer[at + 9:start]))
        if label is None:
            break
        if end == start + 1 and buffer[start] == _NONE:
            into.append(((label, None), 4 + length))
        elif end == start + 9 and buffer[start] == _INT:
            into.append(((label, unpack_int(buffer, start + 1)[0]), 4 + length))
        else:
            break
        at = end
    return at


def _compiled() -> DecodeRun | None:
    if not compiled.allowed():
        return None
    try:
        from ._frames import decode_run
    except ImportError:  # built without a C compiler: the reference does the work
        return None
    return decode_run


def _small_frame_writer() -> type | None:
    if _COMPILED_RUN is None:
        return None
    from ._frames import SmallFrameWriter

    return SmallFrameWriter


_COMPILED_RUN = _compiled()
COMPILED: bool = _COMPILED_RUN is not None
decode_run: DecodeRun = _COMPILED_RUN or decode_run_python
# The sender's side: PipeSender.put in C for messages without a payload or with a small int
# (_frames.c), None where nothing was compiled. PipeSender says how it is used.
SmallFrameWriter: type | None = _small_frame_writer()
