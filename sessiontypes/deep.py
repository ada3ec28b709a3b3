"""Run recursive passes over deeply nested types without exhausting the stack.

A sequence of n interactions is a term nested n deep, and every pass over it
(resolution, projection, printing, equality) recurses that deep. Python's
default limits (1,000 frames, 8 MiB of C stack) stop near 1,000
interactions. :func:`run_deep` runs a pass on a helper thread with a large
stack and, while any such pass runs, a raised recursion limit. Beyond
``MAX_DEPTH`` nesting levels the pass reports a :class:`ProtocolError`
instead of crashing.
"""

from __future__ import annotations

import gc
import os
import resource
import sys
import threading
from collections.abc import Callable
from typing import TypeVar

from .errors import ProtocolError

__all__ = ["run_deep", "NestingTooDeepError", "MAX_DEPTH"]

T = TypeVar("T")

MAX_DEPTH = 250_000              # nesting levels a pass may reach
_STACK_BYTES = 2 << 30          # virtual reservation; only touched pages are used
_RECURSION_LIMIT = MAX_DEPTH * 4  # a level costs a few frames (match arms, __eq__)
_MIN_STACK_BYTES = 16 << 20     # below this a helper thread gains nothing over the caller's stack

_state = threading.local()
_guard = threading.Lock()
_active = 0
_saved_limit = sys.getrecursionlimit()


class NestingTooDeepError(ProtocolError):
    """Raised when a protocol nests deeper than :data:`MAX_DEPTH` levels."""

    def __str__(self) -> str:
        return (f"error: protocol nested too deeply (more than about {MAX_DEPTH} levels); "
                "split it into declarations")


def run_deep(function: Callable[..., T], *args: object) -> T:
    """Call ``function(*args)`` where deep recursion is safe; return its result.

    Exceptions propagate to the caller unchanged, except ``RecursionError``
    which becomes :class:`NestingTooDeepError`.
    """
    if getattr(_state, "deep", False):
        return function(*args)
    outcome: list[tuple[bool, object]] = []

    def target() -> None:
        _state.deep = True
        try:
            outcome.append((True, function(*args)))
        except RecursionError:
            outcome.append((False, NestingTooDeepError()))
        except BaseException as error:  # handed to the caller below
            outcome.append((False, error))

    stack = _stack_bytes()
    if stack < _MIN_STACK_BYTES:
        target()  # an address-space limit leaves no room: the caller's stack and recursion limit
    else:
        # Frames scale with the stack: the recursion limit must stop a pass before the stack ends.
        _enter(_RECURSION_LIMIT * stack // _STACK_BYTES)
        try:
            previous = threading.stack_size(stack)
            try:
                worker = threading.Thread(target=target, name="sessiontypes-deep", daemon=True)
                worker.start()
            except RuntimeError:  # "can't start new thread": no room for its stack after all
                worker = None
            finally:
                threading.stack_size(previous)
            if worker is not None:
                worker.join()
        finally:
            _leave()
        if worker is None:
            target()
    _state.deep = False
    ok, value = outcome[0]
    if ok:
        return value  # type: ignore[return-value]
    raise value  # type: ignore[misc]


_gc_was_enabled = False


def _stack_bytes() -> int:
    """The helper thread's stack: ``_STACK_BYTES``, or less under an address-space limit
    (``ulimit -v``, ``prlimit --as``), where a 2 GiB reservation would fail: half the room
    left, so that the pass's own memory still fits."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return _STACK_BYTES
    try:
        with open("/proc/self/statm") as statm:
            used = int(statm.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        used = soft // 2
    page = resource.getpagesize()
    return max(0, min(_STACK_BYTES, (soft - used) // 2) // page * page)


def _enter(recursion_limit: int) -> None:
    global _active, _saved_limit, _gc_was_enabled
    with _guard:
        if _active == 0:
            _saved_limit = sys.getrecursionlimit()
            sys.setrecursionlimit(max(_saved_limit, recursion_limit))
            # The passes build large acyclic trees: the cycle collector would
            # rescan them again and again for nothing (a third of the time on
            # 10,000-interaction protocols). Paused only while a pass runs.
            _gc_was_enabled = gc.isenabled()
            gc.disable()
        _active += 1


def _leave() -> None:
    global _active
    with _guard:
        _active -= 1
        if _active == 0:
            sys.setrecursionlimit(_saved_limit)
            if _gc_was_enabled:
                gc.enable()
