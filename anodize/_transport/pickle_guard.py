"""The guard on pickled payloads: what may travel pickled, and the scan before any unpickling.

A payload of a class the protocol names that is neither a dataclass nor one the codec
encodes itself travels pickled (:mod:`anodize._transport.codec`). Pickle runs code, so a
pickle from the wire is first *scanned* (:func:`scan_pickle`): only the opcodes of builtin
data and of one instance of that class, memo indices in sequence, lengths within the
data. Only then is it unpickled (:func:`unpickle`), by an unpickler that loads that class
and no other global. The class's own ``__new__``, ``__init__`` (through ``__reduce__``),
``__setstate__`` and container methods still run in the receiver: that is the risk a
protocol takes by naming a class that is not a dataclass (the "Pickle on the wire"
decision). The sender runs the same scan, so what a receiver would refuse is refused
when it is sent.
"""

from __future__ import annotations

import dataclasses
import io
import pickle
import pickletools
import sys
from collections.abc import Iterator
from typing import Any

__all__ = ["PICKLE_PROTOCOL", "PickleRefusedError", "scan_pickle", "travels_pickled", "unpickle"]


def unpickle(data: bytes, cls: type) -> object:
    """The one ``cls`` instance ``data`` holds; scan it with :func:`scan_pickle` first.

    Raises:
        PickleRefusedError: the pickle names another global, or a persistent id.
    """
    return _RestrictedUnpickler(io.BytesIO(data), cls).load()


class _RestrictedUnpickler(pickle.Unpickler):
    """Loads one class, the one the frame names and the codec allows (and no other global)."""

    def __init__(self, data: io.BytesIO, cls: type) -> None:
        super().__init__(data)
        self._cls = cls

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) != (self._cls.__module__, self._cls.__qualname__):
            raise PickleRefusedError(f"pickled payload refers to {module}.{name}, which the protocol "
                                     "does not name")
        return self._cls

    def persistent_load(self, pid: Any) -> Any:
        raise PickleRefusedError("pickled payload refers to a persistent id")


# ---- what may travel pickled ------------------------------------------------------------------
PICKLE_PROTOCOL = 5
# Types the codec encodes itself (exactly these types: a subclass the protocol names is pickled).
_OWN_ENCODING = frozenset({type(None), bool, int, float, complex, str, bytes, bytearray,
                           tuple, list, dict, set, frozenset})
_MAX_PICKLE_OPS = 1 << 20  # opcodes one pickled payload may have
_MAX_PICKLE_STACK = 10_000  # items on the unpickler's stack at once (nesting and batches)
_MAX_PICKLE_INT_BYTES = 2048  # as the codec's own ints: about the 4300 digits int() takes


def travels_pickled(cls: type) -> bool:
    """Whether the encoder pickles instances of ``cls`` (so a pickled one may arrive)."""
    if dataclasses.is_dataclass(cls) or cls in _OWN_ENCODING:
        return False
    np = sys.modules.get("numpy")
    return not (np is not None and issubclass(cls, (np.ndarray, np.generic)))  # arrays: their own tags


# What a stack item is, for scan_pickle: plain data, the allowed class itself, an instance of it;
# a string is kept as itself (a tuple ("str", text)), to know what STACK_GLOBAL looks up.
_DATA, _CLASS, _INSTANCE = "data", "class", "instance"
_STRINGS = frozenset({"SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8"})
# Opcodes that take this many items of plain data from the stack and push one.
_TAKES_DATA = {
    **dict.fromkeys(("NONE", "NEWTRUE", "NEWFALSE", "BININT", "BININT1", "BININT2", "LONG1", "LONG4", "BINFLOAT",
                     "SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8", "SHORT_BINBYTES", "BINBYTES", "BINBYTES8",
                     "BYTEARRAY8", "EMPTY_TUPLE", "EMPTY_LIST", "EMPTY_DICT", "EMPTY_SET"), 0),
    "TUPLE1": 1, "TUPLE2": 2, "TUPLE3": 3}
# Opcodes that add the items above the topmost mark to the container below it.
_ADD_MARKED = frozenset({"APPENDS", "SETITEMS", "ADDITEMS"})


class PickleRefusedError(Exception):
    """A reason to refuse a pickle: its message says which opcode, name or length was refused."""


def scan_pickle(data: bytes, cls: type) -> str | None:
    """Why ``data`` is not a plain pickle of one ``cls`` instance (None: it is), before any unpickling.

    Follows the unpickler's stack without building anything. Accepted: the opcodes that
    ``pickle.dumps(obj, protocol=5)`` writes for an instance of an ordinary class holding
    builtin values; ``cls`` (found by ``STACK_GLOBAL`` or ``GLOBAL``) only as what
    ``NEWOBJ``/``NEWOBJ_EX``/``REDUCE`` instantiate; ``BUILD`` only on such an instance; the
    result must be one. Refused besides: memo indices out of sequence (a ``LONG_BINPUT`` of
    2**27 would make the unpickler allocate 2 GiB), ``FRAME`` or data lengths beyond the
    bytes that are there, more than _MAX_PICKLE_OPS opcodes or _MAX_PICKLE_STACK
    stack items, ints longer than _MAX_PICKLE_INT_BYTES.
    """
    try:
        _follow_pickle(data, cls)
    except PickleRefusedError as refused:
        return str(refused)
    except ValueError as error:  # pickletools: truncated data, an unknown opcode, a bad argument
        return f"malformed pickle: {error}"
    return None


def _follow_pickle(data: bytes, cls: type) -> None:
    if data[:1] != pickle.PROTO:
        raise PickleRefusedError(f"pickle protocol 0 or 1 (only 2 to {PICKLE_PROTOCOL})")
    stack: list[object] = []
    marks: list[int] = []
    fence = 0  # where the topmost mark is: nothing below it may be taken before it is closed
    memo: list[object] = []
    allowed = [("str", cls.__module__), ("str", cls.__qualname__)]
    count = stopped_at = -1
    frame_end = previous = 0  # where the current frame ends (no opcode may cross it); the last opcode

    def take(items: int) -> list[object]:
        if len(stack) - fence < items:
            raise PickleRefusedError("the pickle takes more from its stack than it put there")
        taken = stack[len(stack) - items:]
        del stack[len(stack) - items:]
        return taken

    def pop_mark() -> list[object]:
        nonlocal fence
        if not marks:
            raise PickleRefusedError("the pickle closes a mark it never opened")
        start = marks.pop()
        fence = marks[-1] if marks else 0
        taken = stack[start:]
        del stack[start:]
        return taken

    opcodes: Iterator[tuple[pickletools.OpcodeInfo, Any, int | None]] = pickletools.genops(data)
    for opcode, arg, where in opcodes:
        name = opcode.name
        position = where or 0  # genops knows every position when reading bytes
        if previous < frame_end < position:
            # pickle never writes this; CPython 3.11's file unpickler mishandles it (a
            # bytearray straddling a frame's end comes back as a MemoryError and a bytearray
            # freed with its buffer still exported).
            raise PickleRefusedError(f"an opcode crosses the end of its frame at byte {frame_end}")
        previous = position
        count += 1
        if count >= _MAX_PICKLE_OPS:
            raise PickleRefusedError(f"more than {_MAX_PICKLE_OPS} opcodes")
        items = _TAKES_DATA.get(name)
        if items is not None:  # plain data: the commonest opcodes first
            if items and _CLASS in take(items):
                raise PickleRefusedError("the class itself is used as a tuple item: only instances of it may travel")
            if name in _STRINGS:
                stack.append(("str", arg))
                continue
            if (name == "LONG1" or name == "LONG4") and (arg.bit_length() + 8) // 8 > _MAX_PICKLE_INT_BYTES:
                raise PickleRefusedError(f"an int of more than {_MAX_PICKLE_INT_BYTES} bytes")
            stack.append(_DATA)
            if len(stack) > _MAX_PICKLE_STACK:
                raise PickleRefusedError(f"more than {_MAX_PICKLE_STACK} items on the unpickler's stack")
        elif name == "MEMOIZE":
            if len(stack) <= fence:
                raise PickleRefusedError("the pickle memoizes an item it does not have")
            memo.append(stack[-1])
        elif name in ("BINPUT", "LONG_BINPUT"):
            if arg > len(memo):  # the pickler numbers them 0, 1, 2, ...
                raise PickleRefusedError(f"memo index {arg} out of sequence ({len(memo)} entries so far)")
            if len(stack) <= fence:
                raise PickleRefusedError("the pickle memoizes an item it does not have")
            memo[arg:arg + 1] = [stack[-1]]
        elif name in ("BINGET", "LONG_BINGET"):
            if arg >= len(memo):
                raise PickleRefusedError(f"memo index {arg} was never stored")
            stack.append(memo[arg])
            if len(stack) > _MAX_PICKLE_STACK:
                raise PickleRefusedError(f"more than {_MAX_PICKLE_STACK} items on the unpickler's stack")
        elif name == "MARK":
            marks.append(len(stack))
            fence = len(stack)
        elif name in _ADD_MARKED or name in ("TUPLE", "FROZENSET", "POP_MARK"):
            if _CLASS in pop_mark() and name != "POP_MARK":
                raise PickleRefusedError("the class itself is used as a container item: only instances of it "
                                          "may travel")
            if name in _ADD_MARKED:
                if len(stack) <= fence or stack[-1] == _CLASS:
                    raise PickleRefusedError(f"{name} into something that is not a container or an instance")
            elif name != "POP_MARK":
                stack.append(_DATA)
        elif name in ("APPEND", "SETITEM"):
            if _CLASS in take(1 if name == "APPEND" else 2):
                raise PickleRefusedError("the class itself is used as a container item: only instances of it "
                                          "may travel")
            if len(stack) <= fence or stack[-1] == _CLASS:
                raise PickleRefusedError(f"{name} into something that is not a container or an instance")
        elif name == "POP":
            take(1)
        elif name == "STACK_GLOBAL":  # (the unpickler's find_class allows only this one, too)
            names = take(2)
            if names != allowed:
                looked_up = ".".join(str(n[1]) if isinstance(n, tuple) else "?" for n in names)
                raise PickleRefusedError(f"it refers to {looked_up}, not to the payload's class")
            stack.append(_CLASS)
        elif name == "GLOBAL":
            if arg != f"{cls.__module__} {cls.__qualname__}":
                raise PickleRefusedError(f"it refers to {str(arg).replace(' ', '.')}, not to the payload's class")
            stack.append(_CLASS)
        elif name in ("NEWOBJ", "NEWOBJ_EX", "REDUCE"):  # cls.__new__(cls, *args) or cls(*args)
            made, *args = take(3 if name == "NEWOBJ_EX" else 2)
            if made != _CLASS or any(a in (_CLASS, _INSTANCE) for a in args):
                raise PickleRefusedError(f"{name} of something other than the payload's class")
            stack.append(_INSTANCE)
        elif name == "BUILD":  # instance.__setstate__(state), or its attributes set
            instance, state = take(2)
            if instance != _INSTANCE or state in (_CLASS, _INSTANCE):
                raise PickleRefusedError("BUILD of something other than an instance of the payload's class")
            stack.append(_INSTANCE)
        elif name == "FRAME":
            if arg > len(data) - position - 9:
                raise PickleRefusedError(f"a frame of {arg} bytes, more than the pickle has left")
            if position < frame_end:
                raise PickleRefusedError(f"a frame starts inside the frame that ends at byte {frame_end}")
            frame_end = position + 9 + arg
        elif name == "PROTO":
            if position != 0 or not 2 <= arg <= PICKLE_PROTOCOL:
                raise PickleRefusedError(f"pickle protocol {arg} (only 2 to {PICKLE_PROTOCOL}, at the start)")
        elif name == "STOP":
            if marks or stack != [_INSTANCE]:
                raise PickleRefusedError("the pickle does not hold exactly one instance of the payload's class")
            stopped_at = position
        else:
            raise PickleRefusedError(f"opcode {name} is not allowed in a pickled payload")
    if stopped_at != len(data) - 1:
        raise PickleRefusedError(f"{len(data) - 1 - stopped_at} bytes after the pickle's end")
    if previous < frame_end < len(data):
        raise PickleRefusedError(f"an opcode crosses the end of its frame at byte {frame_end}")
