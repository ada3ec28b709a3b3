# The compiled hot path (_frames.c); see anodize/transport/frames.py for what it does.
from collections import deque

def decode_run(buffer: bytearray, at: int, names: dict[bytes, str], into: deque[tuple[object, int]], /) -> int: ...
