"""Shared-memory rings: large numpy arrays cross processes without being serialized.

Each sending channel owns a ring: a sealed shared-memory segment
(:mod:`anodize._transport.segments`) holding a header page (one state byte per slot,
and the geometry) and ``slots`` equal, page-aligned slots. To send an array the
sender claims a free slot, copies the array in (one ``memcpy``), and passes only the
slot's address through the monitored channel. The receiver maps the slot and gets a
read-only array *viewing* it: no copy. The slot is a linear resource: it is released
(its byte set back to free) when the last array viewing it is garbage collected, so
no code can read a slot after it was released, and the sender never writes into a
slot still in use.

A held slot never stalls the session. A sender finding every slot held by the
receiver (a window of frames it keeps, an array caught in a reference cycle) does
not wait: :meth:`ArrayRing.write` answers None and the codec copies the array into
the frame instead, so the receiver ends up with a private copy, counted in its own
memory and so under its own bound. Only an array too big for a frame waits for a
slot, for a bounded time, and then fails with :class:`RingFullError`.

An array made in a slot (:meth:`ArrayRing.claim_array`) is handed over when it is
sent, without changing a page's protection: the array, and the one array every numpy
view of it leads to through ``base``, become read-only (numpy then refuses a write
through them, or through a view made later). A view made before the send that is
still alive is counted (it holds that array), and then the slot's pages are made
read-only for the sender too (``mprotect``, the strict hand-over), so a write through
it faults in the sender, its own fault, instead of changing the receiver's data; a
strict buffer (``strict=True``) is always handed over so. Each slot has a claim
number: sending an array whose slot was reused since it was made raises
:class:`StaleBufferError`. What no check sees, taken before the send: a raw pointer (a
memoryview, ``ctypes``, C code), ``as_strided``, a view as a numpy subclass (it holds the
buffer, not its base); ask for a strict buffer where one is. A received
array's ``base`` holds the slot's address and layout only: nothing reachable from it
maps the ring's header, which only the reader writes. Both sides map a ring with its
pages present (``MAP_POPULATE``): no page fault the first time a slot is used.

A ring whose slots are too small for an array is replaced by a bigger one (a
new *generation*); old ones stay mapped while arrays view them. Segments are memfds:
they vanish with the processes that hold them, so there is nothing to clean up in
``/dev/shm`` (see :func:`remove_run_segments`).
"""

from __future__ import annotations

import contextlib
import glob
import itertools
import math
import mmap
import os
import secrets
import socket
import struct
import sys
import tempfile
import time
import weakref
from collections.abc import Callable
from typing import Any

from ..errors import AnodizeError
from . import segments
from .segments import PAGE

__all__ = ["ArrayRing", "RingReader", "RingFullError", "RingAllocationError", "StaleBufferError", "DEFAULT_SLOTS",
           "DEFAULT_INLINE_MAX", "remove_run_segments", "remove_stale_segments", "segment_dir"]

FREE, BUSY = 0, 1
_HEADER = max(4096, PAGE)  # the first page: one state byte per slot, and the geometry at its end
_GEOMETRY = struct.Struct("<QQ")  # (slots, slot size), at _HEADER - 16
_READ = struct.Struct("<Q")  # arrays the reader has taken out of the ring, at _HEADER - 24 (the reader writes it)
_MAX_SLOTS = _HEADER - _GEOMETRY.size - _READ.size
DEFAULT_SLOTS = 8
DEFAULT_INLINE_MAX = 32 * 2**20  # copied into a frame when no slot is free (the codec's cap is 64 MiB)
DEFAULT_PATIENCE = 10.0  # seconds an array too big to go inline waits for a slot


def _size(nbytes: int) -> str:
    return f"{nbytes / 2**30:.1f} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:.1f} MiB"


class RingFullError(AnodizeError):
    """Raised by a send when the receiver holds every slot of the channel's ring (or has
    not taken the rings handed to it), nothing came back in time, and the array is too
    big to be copied into a frame instead.

    Attributes:
        channel: ``sender->receiver``.
        nbytes: the array's size.
        slots, slot_size: the ring's geometry.
        waited: seconds the sender waited.
        inline_max: the largest array that may travel copied in a frame.
        inbox_full: True when what the receiver has not taken is rings, not slots.
    """

    def __init__(self, channel: str, nbytes: int, slots: int, slot_size: int, waited: float,
                 inline_max: int, inbox_full: bool = False) -> None:
        self.channel, self.nbytes, self.slots, self.slot_size = channel, nbytes, slots, slot_size
        self.waited, self.inline_max, self.inbox_full = waited, inline_max, inbox_full
        super().__init__(str(self))

    def __str__(self) -> str:
        if self.inbox_full:
            held = ("the receiver has not taken the shared-memory rings handed to it (its inbox is full), "
                    f"none was taken within {self.waited:g} s")
        else:
            held = (f"the receiver holds all {self.slots} slots of its shared-memory ring "
                    f"({_size(self.slot_size)} each: arrays it received and still keeps alive), none came "
                    f"back within {self.waited:g} s")
        return (f"cannot send a {_size(self.nbytes)} array on channel {self.channel}: {held}, and an array "
                f"over {_size(self.inline_max)} cannot be copied into a frame instead")


class RingAllocationError(AnodizeError):
    """Raised by a send (or :meth:`ArrayRing.claim_array`) when the memory for a ring
    cannot be had: the machine or the memory cgroup has not that much left.

    Attributes:
        channel: ``sender->receiver``.
        nbytes: the ring's size; ``slots`` and ``slot_size`` its geometry.
        reason: what the kernel (or the check before asking it) said.
    """

    def __init__(self, channel: str, nbytes: int, slots: int, slot_size: int, reason: str) -> None:
        self.channel, self.nbytes, self.slots, self.slot_size, self.reason = channel, nbytes, slots, slot_size, reason
        super().__init__(str(self))

    def __str__(self) -> str:
        return (f"cannot allocate a {_size(self.nbytes)} shared-memory ring for channel {self.channel} "
                f"({self.slots} slots of {_size(self.slot_size)}): {self.reason}")


class StaleBufferError(AnodizeError, ValueError):
    """Raised by a send given an array from ``ep.buffer()`` (or a view of one) that was
    sent before and whose shared-memory slot has since been filled with a later frame:
    what it shows is no longer what was written into it.

    Attributes:
        channel: ``sender->receiver``, the channel the buffer was made for.
        slot: the slot it lives in.
        claim: the slot's claim number when the buffer was made; ``current``: now.
    """

    def __init__(self, channel: str, slot: int, claim: int, current: int) -> None:
        self.channel, self.slot, self.claim, self.current = channel, slot, claim, current
        super().__init__(str(self))

    def __str__(self) -> str:
        return (f"cannot send an array from ep.buffer() made for channel {self.channel}: it was sent already and "
                f"its shared-memory slot {self.slot} has been filled again since (claim {self.claim}, now "
                f"{self.current}); expected a fresh ep.buffer() for each frame, got a stale one")


def segment_dir() -> str:
    """Where ring files lived before rings were memfds: ``/dev/shm`` (RAM) where it exists."""
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


def remove_run_segments(run_id: str) -> int:
    """Nothing to do: a run's rings are memfds, which vanish with the last process holding
    them (a crashed group's too). Kept for the supervisor, which calls it at a run's end.

    Returns:
        0 (the number of files removed).
    """
    return 0


def remove_stale_segments() -> int:
    """Delete ring files in ``/dev/shm`` left by earlier versions (which made files there)
    of runs whose supervisor is dead; returns how many there were."""
    removed = 0
    for path in glob.glob(os.path.join(segment_dir(), "anodize-*-*")):
        owner = os.path.basename(path).split("-")[1]
        if owner.isdigit() and not _alive(int(owner)):
            try:
                os.unlink(path)
                removed += 1
            except OSError:
                pass
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


# Segments of this process by name, for a reader in the same process (tests; no inbox).
_LOCAL: dict[str, int] = {}


class _Segment:
    """One generation of a ring, as its sender has it."""

    __slots__ = (
        "__weakref__",
        "address",
        "claims",
        "fd",
        "generation",
        "handed_over",
        "map",
        "name",
        "protected",
        "protections",
        "quarantine",
        "sent",
        "slot_size",
        "slots",
    )

    def __init__(self, name: str, slots: int, slot_size: int, generation: int) -> None:
        self.name, self.slots, self.slot_size, self.generation = name, slots, slot_size, generation
        self.fd, self.map = segments.create(name, _HEADER + slots * slot_size)
        _GEOMETRY.pack_into(self.map, _HEADER - _GEOMETRY.size, slots, slot_size)
        self.address = segments.address_of(self.map)
        self.protected = bytearray(slots)  # slots read-only here since they were sent in place (strictly)
        self.protections = 0  # mprotect calls: page-table changes, made only by a strict hand-over
        # Slots handed over strictly: not filled again while the sender's old buffer memory (and so
        # any view of it) lives, else making the slot writable again would let that view write
        # into a later frame the receiver reads.
        self.quarantine: dict[int, weakref.ref[Any]] = {}
        self.claims = [0] * slots  # per slot: how often it was filled (a buffer made at an older count is stale)
        self.handed_over = False
        self.sent = 0  # arrays sent through this generation's slots
        _LOCAL[name] = self.fd
        weakref.finalize(self, _close_segment, name, self.fd)

    def take_free(self) -> int:
        """Claim the lowest free slot (one freed a moment ago is still in the CPU's caches) that no
        view from a strict hand-over still reaches; -1: none."""
        slot = self.map.find(b"\x00", 0, self.slots)
        while slot >= 0 and self.quarantine:
            held = self.quarantine.get(slot)
            if held is None or held() is None:
                self.quarantine.pop(slot, None)
                break
            slot = self.map.find(b"\x00", slot + 1, self.slots)
        if slot >= 0:
            self.map[slot] = BUSY
            self.claims[slot] += 1
        return slot

    def offset(self, slot: int) -> int:
        return _HEADER + slot * self.slot_size

    def in_flight(self) -> int:
        """Arrays sent through the slots that the reader has not taken yet (still in the pipe)."""
        read: int = _READ.unpack_from(self.map, _HEADER - _GEOMETRY.size - _READ.size)[0]
        return self.sent - read

    def set_writable(self, slot: int, writable: bool) -> None:
        if self.protected[slot] == (not writable):
            return
        segments.protect(self.address + self.offset(slot), self.slot_size, writable)
        self.protected[slot] = not writable
        self.protections += 1


def _close_segment(name: str, fd: int) -> None:
    if _LOCAL.get(name) == fd:
        del _LOCAL[name]
    os.close(fd)


class _Claim:
    """Which filling of a slot a sender's buffer was made for (its claim number then)."""

    __slots__ = ("channel", "claims", "number", "slot")

    def __init__(self, channel: str, slot: int, claims: list[int]) -> None:
        self.channel, self.slot, self.claims, self.number = channel, slot, claims, claims[slot]

    def check(self) -> None:
        """Raise :class:`StaleBufferError` if the slot was filled again since."""
        current = self.claims[self.slot]
        if current != self.number:
            raise StaleBufferError(self.channel, self.slot, self.number, current)


class _SlotMemory:
    """The ``base`` of an array in a slot: the slot's address and layout, nothing that maps
    the ring, and no buffer (so numpy refuses to make a read-only array writable again).
    A sender's buffer also has its :class:`_Claim`; a received array has none."""

    __slots__ = ("__array_interface__", "__weakref__", "claim")

    def __init__(self, address: int, shape: tuple[int, ...], typestr: str, readonly: bool,
                 claim: _Claim | None = None) -> None:
        self.__array_interface__: dict[str, Any] = {"data": (address, readonly), "shape": shape,
                                                     "typestr": typestr, "version": 3}
        self.claim = claim


class _Claimed:
    """A buffer handed out and not sent yet: weak references to the array the caller got
    and to its base (the one array every numpy view of it holds), and how to hand it over."""

    __slots__ = ("root", "strict", "token", "user")

    def __init__(self, token: int, root: Any, user: Any, strict: bool) -> None:
        self.token, self.strict = token, strict
        self.root, self.user = weakref.ref(root), weakref.ref(user)


_UNCOUNTED: list[int] = []  # references getrefcount sees besides the holders (calibrated once)


def _holders(obj: object, calibrating: bool = False) -> int:
    """How many objects hold ``obj``, not counting the caller's local variable: the references
    ``sys.getrefcount`` sees, less those it sees, called the same way, for an object with
    one known holder (so an interpreter that counts locals differently still agrees)."""
    references = sys.getrefcount(obj)
    if calibrating:
        return references
    if not _UNCOUNTED:
        probe = [object()]
        held = probe[0]
        _UNCOUNTED.append(_holders(held, calibrating=True) - 1)
    return references - _UNCOUNTED[0]


def check_fresh(array: Any) -> None:
    """Raise :class:`StaleBufferError` if ``array`` is (a view of) a sender's buffer whose slot
    was filled again after it was sent. A view's ``base`` is the buffer's base array, whose
    ``base`` is the slot's memory."""
    memory = array.base
    if memory is not None and type(memory) is not _SlotMemory:
        memory = getattr(memory, "base", None)
    if type(memory) is _SlotMemory and memory.claim is not None:
        memory.claim.check()


class ArrayRing:
    """The sending side: copies arrays into free slots, or hands over slots filled in place.

    Args:
        prefix: the start of the ring's names, unique to the run, the channel and the incarnation.
        slots: how many arrays may be in flight (held by the receiver) at once.
        peer_gone: returns a reason to give up (e.g. the receiver failed) or None.
        inbox: the key of the receiver's :class:`~anodize._transport.segments.Inbox`, where
            the ring's segments are sent (None: the reader is in this process).
        channel: ``sender->receiver``, for error messages.
        inline_max: the largest array copied into a frame when no slot is free.
        patience: seconds a bigger array waits for a slot before :class:`RingFullError`.
        strict: hand every buffer over by making its pages read-only here (``mprotect``),
            as :meth:`claim_array` does for a strict buffer.
    """

    def __init__(self, prefix: str, slots: int = DEFAULT_SLOTS,
                 peer_gone: Callable[[], str | None] = lambda: None, inbox: str | None = None,
                 channel: str = "", inline_max: int = DEFAULT_INLINE_MAX,
                 patience: float = DEFAULT_PATIENCE, strict: bool = False) -> None:
        if not 0 < slots <= _MAX_SLOTS:
            raise ValueError(f"a ring has 1 to {_MAX_SLOTS} slots, not {slots}")
        self.prefix = prefix
        self.slots = slots
        self.peer_gone = peer_gone
        self.inbox = inbox
        self.channel = channel or prefix
        self.inline_max = inline_max
        self.patience = patience
        self.strict = strict
        self._current: _Segment | None = None
        self._old: list[_Segment] = []  # earlier generations: their fds stay open for late readers
        self._claimed: dict[tuple[int, int], _Claimed] = {}  # (generation, slot) -> the claim
        self._socket: socket.socket | None = None

    @property
    def slot_size(self) -> int:
        """Bytes per slot of the current generation (0 before the first array)."""
        return 0 if self._current is None else self._current.slot_size

    @property
    def name(self) -> str:
        """The current generation's name ("" before the first array)."""
        return "" if self._current is None else self._current.name

    def write(self, array: Any) -> tuple[str, int, int] | None:
        """Put ``array`` in a slot; return (ring name, slot, byte offset), or None when no
        slot is free and the array is small enough to travel copied in the frame instead.

        An array claimed with :meth:`claim_array` is handed over as it is (no copy).

        Raises:
            BrokenPipeError: the receiver is gone (``peer_gone`` said so).
            RingFullError: no slot came back in time for an array too big to go inline.
            RingAllocationError: no memory for a bigger ring.
            StaleBufferError: ``array`` is a buffer sent before whose slot was filled again.
        """
        import numpy as np

        claim = self._claim_of(array)
        if claim is None and array.base is not None:
            check_fresh(array)
        nbytes = array.nbytes
        if claim is None and (self._current is None or nbytes > self._current.slot_size):
            self._grow(nbytes)
        segment = self._current
        assert segment is not None
        if not self._hand_over(segment, nbytes):
            return None  # the receiver has not taken our earlier rings yet: inline this time
        if claim is not None:
            return self._hand_in_place(segment, array, claim)
        slot = segment.take_free()
        if slot < 0:
            slot = self._wait_for_slot(segment, nbytes)
            if slot < 0:
                return None
        offset = segment.offset(slot)
        segment.set_writable(slot, True)  # once sent in place, now ours to fill again
        np.copyto(np.ndarray(array.shape, array.dtype, buffer=segment.map, offset=offset), array, casting="no")
        segment.sent += 1
        return segment.name, slot, offset

    def claim_array(self, shape: tuple[int, ...], dtype: Any, strict: bool = False) -> Any:
        """A writable array in a claimed slot: fill it, send it, and nothing is copied.

        Sending it hands the slot over: the array becomes read-only here, and so does
        every numpy view of it made later. A view made before the send and still alive
        makes the hand-over strict: the slot's pages become read-only here (so a write
        through that view faults), until the slot is claimed again. ``strict``: always
        so (for a buffer whose address was given to C code or ctypes, which no check
        sees). Sending it again once its slot was reused raises :class:`StaleBufferError`.
        An array never sent gives its slot back when it is collected. With every slot
        held by the receiver, this is an ordinary array, which is sent by copying.

        Raises:
            RingAllocationError: no memory for a ring big enough.
        """
        import numpy as np

        dt = np.dtype(dtype)
        nbytes = dt.itemsize * math.prod(shape)
        if nbytes == 0:
            return np.empty(shape, dt)
        if self._current is None or nbytes > self._current.slot_size:
            self._grow(nbytes)
        segment = self._current
        assert segment is not None
        slot = segment.take_free()
        if slot < 0:
            return np.empty(shape, dt)  # every slot is held: an ordinary array, sent by copying
        segment.set_writable(slot, True)  # a strict hand-over left it read-only
        memory = _SlotMemory(segment.address + segment.offset(slot), tuple(shape), dt.str, readonly=False,
                             claim=_Claim(self.channel, slot, segment.claims))
        root = np.asarray(memory)
        # The caller gets a view of ``root``: every numpy view made of it then has ``root`` as its
        # base, so the references to ``root`` count the views alive when it is sent.
        array = root.view()
        token = next(_tokens)
        self._claimed[(segment.generation, slot)] = _Claimed(token, root, array, strict or self.strict)
        weakref.finalize(memory, self._unclaim, segment, slot, token)  # keeps the segment mapped
        return array

    @property
    def page_protections(self) -> int:
        """``mprotect`` calls made so far, over every generation (strict hand-overs only)."""
        return sum(segment.protections for segment in self._old) + (
            self._current.protections if self._current else 0)

    @property
    def arrays_sent(self) -> int:
        """Arrays handed to the receiver through slots, over every generation (copied or in place)."""
        return sum(segment.sent for segment in self._old) + (self._current.sent if self._current else 0)

    def owns(self, array: Any) -> bool:
        """Whether ``array`` is a claimed, unsent slot of the current ring.

        Raises:
            StaleBufferError: ``array`` is a buffer sent before whose slot was filled again.
        """
        if self._claim_of(array) is not None:
            return True
        if array.base is not None:
            check_fresh(array)
        return False

    def in_use(self) -> int:
        """Slots of the current generation that are not free (held by the receiver or claimed)."""
        segment = self._current
        return 0 if segment is None else sum(segment.map[i] != FREE for i in range(segment.slots))

    # ---- internals ---------------------------------------------------------------------
    def _grow(self, nbytes: int) -> None:
        old = self._current
        generation = 1 if old is None else old.generation + 1
        slot_size = -(-max(nbytes, 2 * (old.slot_size if old else 0), 1) // PAGE) * PAGE
        name = f"{self.prefix}-{generation}-{secrets.token_hex(4)}"  # unguessable: no forged hand-over
        total = _HEADER + self.slots * slot_size
        available = segments.available_memory()
        if available is not None and total > available:
            raise RingAllocationError(self.channel, total, self.slots, slot_size,
                                      f"only {_size(available)} of memory is available")
        try:
            segment = _Segment(name, self.slots, slot_size, generation)
        except OSError as error:
            raise RingAllocationError(self.channel, total, self.slots, slot_size, str(error)) from None
        if old is not None:
            self._old.append(old)
        self._current = segment

    def _hand_over(self, segment: _Segment, nbytes: int) -> bool:
        """Send the receiver the current segment before its first slot; False: not now."""
        if segment.handed_over or self.inbox is None:
            return True
        if self._socket is None:
            self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
        deadline = None
        delay = 0.0005
        while True:
            try:
                done = segments.hand_over(self._socket, self.inbox, segment.name, segment.fd)
            except (ConnectionRefusedError, FileNotFoundError):
                raise BrokenPipeError(self.peer_gone() or "the receiver's process has ended") from None
            if done:
                segment.handed_over = True
                return True
            # Its inbox is full of our earlier rings: it takes them as it reads the frames naming them.
            if nbytes <= self.inline_max:
                return False
            deadline = deadline or time.monotonic() + self.patience
            if time.monotonic() > deadline:
                raise RingFullError(self.channel, nbytes, self.slots, segment.slot_size, self.patience,
                                    self.inline_max, inbox_full=True)
            delay = self._pause(delay)

    def _wait_for_slot(self, segment: _Segment, nbytes: int) -> int:
        """A slot for an array that found none free; -1: send it inline instead.

        While arrays we sent are still on their way (the receiver is behind), their slots
        come back as it takes and drops them: wait, as a full pipe makes a sender wait.
        Once it has taken every one and still holds every slot, it keeps them (a window
        of frames, a reference cycle): no slot may come back, so do not wait for one.
        """
        reason = self.peer_gone()
        if reason is not None:  # not even inline: the frame would go nowhere
            raise BrokenPipeError(reason)
        deadline = None
        delay = 0.00005
        while True:
            if segment.in_flight() <= 0:
                if nbytes <= self.inline_max:
                    return -1
                deadline = deadline or time.monotonic() + self.patience
                if time.monotonic() > deadline:
                    raise RingFullError(self.channel, nbytes, self.slots, segment.slot_size, self.patience,
                                        self.inline_max)
            delay = self._pause(delay)
            slot = segment.take_free()
            if slot >= 0:
                return slot

    def _pause(self, delay: float) -> float:
        """Sleep ``delay`` (never spin), unless the receiver is gone; the next delay."""
        reason = self.peer_gone()
        if reason is not None:
            raise BrokenPipeError(reason)
        time.sleep(delay)
        return min(delay * 2, 0.002)

    def _claim_of(self, array: Any) -> tuple[int, int] | None:
        """(slot, offset) if ``array`` is a claimed, unsent buffer of the current ring, or a
        C-contiguous view of one that starts its slot (not an older buffer of the same slot)."""
        segment = self._current
        root = array.base
        if not self._claimed or segment is None or root is None:
            return None  # (an array owning its memory, as most sent by copying do, is no buffer)
        memory = getattr(root, "base", None)
        if type(memory) is not _SlotMemory:  # the buffer's root itself, or no buffer at all
            root, memory = array, root
            if type(memory) is not _SlotMemory:
                return None
        claim = memory.claim
        if claim is None:
            return None  # a received array
        claimed = self._claimed.get((segment.generation, claim.slot))
        if claimed is None or claimed.root() is not root or not array.flags.c_contiguous:
            return None
        if array is not claimed.user() and \
                array.__array_interface__["data"][0] != memory.__array_interface__["data"][0]:
            return None  # a view that does not start the slot: sent by copying
        return claim.slot, segment.offset(claim.slot)

    def _hand_in_place(self, segment: _Segment, array: Any, claim: tuple[int, int]) -> tuple[str, int, int]:
        slot, offset = claim
        claimed = self._claimed.pop((segment.generation, slot))
        segment.sent += 1
        if claimed.strict or self._views_unseen(array, claimed):
            segment.set_writable(slot, False)  # the receiver's now: a write through any view faults here
            root = claimed.root()
            if root is not None:  # every numpy view of the buffer keeps its memory object alive
                segment.quarantine[slot] = weakref.ref(root.base)
        # Numpy refuses writes through these, and through views of them made from now on.
        array.flags.writeable = False
        user, root = claimed.user(), claimed.root()
        if user is not None and user is not array:
            user.flags.writeable = False
        if root is not None:
            root.flags.writeable = False
            memory = root.base  # an array made from the slot's memory itself is read-only too
            memory.__array_interface__["data"] = (memory.__array_interface__["data"][0], True)
        return segment.name, slot, offset

    @staticmethod
    def _views_unseen(array: Any, claimed: _Claimed) -> bool:
        """Whether a view of the buffer made before the send is still alive (beyond ``array``
        and the buffer itself): such a view keeps its writable flag, so only the page
        protection can stop a write through it."""
        root = claimed.root()
        if root is None or array.base is not root:
            return True  # not sent as the buffer or a view of it: cannot count, be strict
        user = claimed.user()
        known = 1 + (user is not None and user is not array and user.base is root)
        # Every live view holds ``root``; the slot's memory holder is held by ``root`` alone,
        # unless an array was made from it.
        memory = root.base  # a local, as _holders counts on
        return _holders(root) > known or _holders(memory) > 1

    def _sent_in_place(self, array: Any) -> tuple[str, int, int] | None:
        """Hand ``array`` over if it is a claimed slot of the current ring: its address, or None."""
        claim = self._claim_of(array)
        segment = self._current
        if claim is None or segment is None or not self._hand_over(segment, array.nbytes):
            return None
        return self._hand_in_place(segment, array, claim)

    def _unclaim(self, segment: _Segment, slot: int, token: int) -> None:
        claimed = self._claimed.get((segment.generation, slot))
        if claimed is not None and claimed.token == token:  # this claim, never sent
            del self._claimed[(segment.generation, slot)]
            segment.map[slot] = FREE


class _Mapped:
    """A ring as a reader has it: the header read-write, the slots read-only."""

    __slots__ = ("address", "header", "name", "read", "slot_size", "slots", "slots_map")

    def __init__(self, name: str, fd: int) -> None:
        size = segments.verify(fd, name)
        geometry = os.pread(fd, _GEOMETRY.size, _HEADER - _GEOMETRY.size)
        if size < _HEADER or len(geometry) != _GEOMETRY.size:
            raise ValueError(f"ring {name} is {size} bytes: no room for its header")
        # Read once: the sender could rewrite the header's geometry later.
        self.slots, self.slot_size = _GEOMETRY.unpack(geometry)
        if not 0 < self.slots <= _MAX_SLOTS or self.slot_size <= 0 or self.slot_size % PAGE \
                or size != _HEADER + self.slots * self.slot_size:
            raise ValueError(f"ring {name} is {size} bytes, which does not match its {self.slots} slots "
                             f"of {self.slot_size} bytes")
        self.name = name
        self.read = 0  # arrays taken out of it (the sender waits for a slot only while some are not)
        self.header = mmap.mmap(fd, _HEADER)
        self.slots_map = mmap.mmap(fd, size - _HEADER, flags=segments.SHARED_POPULATED, prot=mmap.PROT_READ,
                                   offset=_HEADER)
        self.address = segments.address_of(self.slots_map)


class RingReader:
    """The receiving side: maps rings by name and hands out read-only arrays viewing slots.

    Args:
        inbox: the key its sender hands the ring's segments over to (None: the
            rings are in this process).

    Raises:
        OSError: the inbox's address is taken.
    """

    def __init__(self, inbox: str | None = None) -> None:
        self._maps: dict[str, _Mapped] = {}
        self._viewed: set[tuple[str, int]] = set()  # slots with a live view here
        self._inbox = segments.Inbox(inbox) if inbox is not None else None

    def read(self, name: str, slot: int, offset: int, dtype: str, shape: tuple[int, ...],
             prefix: str = "anodize-") -> Any:
        """A read-only array viewing ``slot`` of ring ``name``; the slot is freed when it is collected.

        ``prefix`` is what the channel's ring names must start with (a sender may
        only point into its own rings).

        Raises:
            ValueError: the address is not a filled slot of one of the sender's rings.
        """
        import numpy as np

        if not name.startswith(prefix) or "/" in name:
            raise ValueError(f"ring {name!r} does not belong to this channel")
        ring = self._maps.get(name)
        if ring is None:
            ring = self._maps[name] = self._map(name)
        dt = np.dtype(dtype)
        if not 0 <= slot < ring.slots or offset != _HEADER + slot * ring.slot_size or \
                dt.itemsize * math.prod(shape) > ring.slot_size or ring.header[slot] != BUSY or \
                (name, slot) in self._viewed:
            raise ValueError(f"slot {slot} at offset {offset} is not a filled slot of ring {name}")
        memory = _SlotMemory(ring.address + slot * ring.slot_size, tuple(shape), dt.str, readonly=True)
        array = np.asarray(memory)
        self._viewed.add((name, slot))
        ring.read += 1
        _READ.pack_into(ring.header, _HEADER - _GEOMETRY.size - _READ.size, ring.read)
        # The finalizer, not the array, keeps the mapping alive: nothing in the array leads to it.
        weakref.finalize(memory, self._release, ring, slot)
        return array

    def _map(self, name: str) -> _Mapped:
        fd = self._inbox.take(name) if self._inbox is not None else None
        if fd is None and name in _LOCAL:
            fd = os.dup(_LOCAL[name])
        if fd is None:
            raise ValueError(f"ring {name} was never handed over to this receiver")
        try:
            return _Mapped(name, fd)
        finally:
            os.close(fd)  # the mappings keep the memory

    def _release(self, ring: _Mapped, slot: int) -> None:
        self._viewed.discard((ring.name, slot))
        with contextlib.suppress(ValueError):  # closed at interpreter exit
            ring.header[slot] = FREE


_tokens = itertools.count()
