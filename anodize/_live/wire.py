"""Frames between the groups and the supervisor on the live view's UNIX socket.

A frame is ``length (u32) | kind (1 byte) | label index (u16) | time in ns (i64) | data``.
One thread writes each direction of a socket, so frames never interleave.
"""

from __future__ import annotations

import socket
import struct

__all__ = ["HELLO", "MESSAGE", "INPUT", "STATS", "WANT", "send_frame", "read_frame"]

HELLO = b"H"    # group -> supervisor: data is the group's name
MESSAGE = b"M"  # group -> supervisor: a tapped message (CDR)
STATS = b"S"    # group -> supervisor, last: what the group's tap thinned or dropped (JSON)
INPUT = b"I"    # supervisor -> group: a client's message for the label's sender (CDR)
WANT = b"W"     # supervisor -> group, on demand (introspection): what the label's messages are wanted
                # for now, in the time field: 0 nothing, 1 their times only (hz), 2 the messages (echo)

_HEADER = struct.Struct("<IcHq")
_MAX_FRAME = 1 << 30


def send_frame(sock: socket.socket, kind: bytes, index: int, stamp: int, data: bytes) -> None:
    """Write one frame (blocking until the kernel takes it).

    Raises:
        OSError: the other end is gone.
    """
    sock.sendall(_HEADER.pack(_HEADER.size - 4 + len(data), kind, index, stamp))
    if data:
        sock.sendall(data)


def read_frame(sock: socket.socket) -> tuple[bytes, int, int, bytes] | None:
    """The next frame ``(kind, index, stamp, data)``, or None at the end of the stream.

    Raises:
        OSError: the socket failed, or the frame is not one of ours.
    """
    head = _read_exactly(sock, _HEADER.size)
    if head is None:
        return None
    length, kind, index, stamp = _HEADER.unpack(head)
    if not _HEADER.size - 4 <= length <= _MAX_FRAME:
        raise OSError(f"live view: a frame of {length} bytes")
    data = _read_exactly(sock, length - (_HEADER.size - 4))
    if data is None:
        return None
    return kind, index, stamp, data


def _read_exactly(sock: socket.socket, size: int) -> bytes | None:
    buffer = bytearray(size)
    view = memoryview(buffer)
    got = 0
    while got < size:
        n = sock.recv_into(view[got:])
        if n == 0:
            return None
        got += n
    return bytes(buffer)
