# The compiled hot path (_frames.c); see anodize/transport/frames.py for what it does.
from collections import deque
from collections.abc import Callable

def decode_run(buffer: bytearray, at: int, names: dict[bytes, str], into: deque[tuple[object, int]], /) -> int: ...

class SmallFrameWriter:
    def __init__(self, fd: int, empty_frames: dict[str, bytes], int_prefixes: dict[str, bytes],
                 fallback: Callable[[object], None]) -> None: ...
    def __call__(self, item: object, /) -> None: ...
