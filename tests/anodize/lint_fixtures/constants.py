"""Nothing here is shared state: constants, imports, functions, frozen values, locals."""

import math
from dataclasses import dataclass
from os.path import join

LIMIT = 3
NAMES = ("P", "C")
EMPTY = frozenset()
GREETING = "hello"
RATE = 2.5
_buffer = []  # shadowed by a local in each role


@dataclass(frozen=True)
class Point:
    x: int
    y: int


ORIGIN = Point(0, 0)


def scale(value):
    return value * RATE


def producer(ep):
    _buffer = [scale(i) for i in range(LIMIT)]
    for item in _buffer:
        ep.send("C", "data", math.floor(item))
    ep.send("C", "stop")
    return join(GREETING, NAMES[0]), ORIGIN, EMPTY


def consumer(ep, _buffer=None):
    _buffer = []
    while (message := ep.recv("P")).label == "data":
        _buffer.append(scale(message.payload))
    return ORIGIN.x, LIMIT
