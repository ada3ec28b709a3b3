"""Shared-memory rings: large numpy arrays cross processes without being serialized.

Each sending channel owns a ring: one file in ``/dev/shm`` holding a header
(one state byte per slot) and ``slots`` equal slots. To send an array the sender
claims a free slot, copies the array in, and passes only the slot's address
through the monitored channel. The receiver maps the slot and gets an array
*viewing* it: no copy. The slot is a linear resource: it is released (its byte
set back to free) when the last array viewing it is garbage collected, so no
code can read a slot after it was released, and the sender never writes into a
slot still in use. A sender finding every slot busy waits for one (back pressure).

A ring whose slots are too small for an array is replaced by a bigger one (a
new *generation*); old rings stay mapped until the run ends, because arrays
viewing them may still be alive. The supervisor removes every ring of a run at
its end (:func:`remove_run_segments`), even those of crashed groups.
"""

from __future__ import annotations

import contextlib
import glob
import itertools
import math
import mmap
import os
import struct
import tempfile
import time
import weakref
from collections.abc import Callable
from typing import Any

__all__ = ["ArrayRing", "RingReader", "remove_run_segments", "remove_stale_segments", "segment_dir"]

FREE, BUSY = 0, 1
_HEADER = 4096  # the first page: one state byte per slot, and the geometry at its end
_GEOMETRY = struct.Struct("<QQ")  # (slots, slot size), at _HEADER - 16
_ALIGN = 4096
DEFAULT_SLOTS = 8


def segment_dir() -> str:
    """Where ring files live: ``/dev/shm`` (RAM) where it exists."""
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


def _path(name: str) -> str:
    return os.path.join(segment_dir(), name)


def remove_run_segments(run_id: str) -> int:
    """Delete every ring file of run ``run_id``; returns how many there were."""
    paths = glob.glob(_path(f"anodize-{run_id}-*"))
    for path in paths:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
    return len(paths)


def remove_stale_segments() -> int:
    """Delete ring files of runs whose supervisor is dead (killed before it could clean up)."""
    removed = 0
    for path in glob.glob(_path("anodize-*-*")):
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


class ArrayRing:
    """The sending side: copies arrays into free slots.

    Args:
        prefix: a file name prefix unique to the run and the channel.
        slots: how many arrays may be in flight (held by the receiver) at once.
        peer_gone: called while waiting for a slot; returns a reason to give up
            (e.g. the receiver failed) or None to keep waiting.
    """

    def __init__(self, prefix: str, slots: int = DEFAULT_SLOTS,
                 peer_gone: Callable[[], str | None] = lambda: None) -> None:
        self.prefix = prefix
        self.slots = slots
        self.peer_gone = peer_gone
        self.generation = 0
        self.slot_size = 0
        self.name = ""
        self._map: mmap.mmap | None = None
        self._old: list[mmap.mmap] = []  # earlier generations, kept while views may live
        self._claimed: dict[int, tuple[int, int, int]] = {}  # slot -> (generation, offset, token)
        self._address = 0  # where the current ring is mapped in this process

    def write(self, array: Any) -> tuple[str, int, int]:
        """Copy ``array`` into a free slot; return (ring name, slot, byte offset).

        Raises:
            BrokenPipeError: the receiver is gone (``peer_gone`` said so) while waiting.
        """
        import numpy as np

        in_place = self._sent_in_place(array)
        if in_place is not None:
            return in_place
        if array.nbytes > self.slot_size:
            self._grow(array.nbytes)
        assert self._map is not None
        slot = self._claim()
        offset = _HEADER + slot * self.slot_size
        target = np.ndarray(array.shape, array.dtype, buffer=self._map, offset=offset)
        np.copyto(target, array, casting="no")
        return self.name, slot, offset

    def _grow(self, nbytes: int) -> None:
        if self._map is not None:
            self._old.append(self._map)
        self.generation += 1
        self.slot_size = -(-max(nbytes, self.slot_size * 2) // _ALIGN) * _ALIGN
        self.name = f"{self.prefix}-{self.generation}"
        fd = os.open(_path(self.name), os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            os.ftruncate(fd, _HEADER + self.slots * self.slot_size)
            self._map = mmap.mmap(fd, _HEADER + self.slots * self.slot_size)
        finally:
            os.close(fd)
        _GEOMETRY.pack_into(self._map, _HEADER - _GEOMETRY.size, self.slots, self.slot_size)
        import numpy as np

        self._address = np.frombuffer(self._map, np.uint8, count=1).__array_interface__["data"][0]
        self._claimed.clear()  # slots claimed in the old ring are sent by copying

    def _claim(self) -> int:
        states = self._map
        assert states is not None
        delay = 0.00005
        while True:
            # The lowest free slot: a slot freed a moment ago is still in the CPU's caches.
            slot = states.find(b"\x00", 0, self.slots)
            if slot >= 0:
                states[slot] = BUSY
                return slot
            reason = self.peer_gone()
            if reason is not None:
                raise BrokenPipeError(reason)
            time.sleep(delay)  # every slot is held by the receiver: wait for one
            delay = min(delay * 2, 0.005)

    def claim_array(self, shape: tuple[int, ...], dtype: Any) -> Any:
        """A writable array in a claimed slot: fill it, send it, and nothing is copied.

        Sending it hands the slot over (the array becomes read-only here); an array
        never sent gives its slot back when it is collected.
        """
        import numpy as np

        dt = np.dtype(dtype)
        nbytes = dt.itemsize * math.prod(shape)
        if nbytes > self.slot_size:
            self._grow(nbytes)
        assert self._map is not None
        slot = self._claim()
        offset = _HEADER + slot * self.slot_size
        root = np.frombuffer(self._map, dt, count=nbytes // dt.itemsize, offset=offset)
        token = next(_tokens)
        self._claimed[slot] = (self.generation, offset, token)
        weakref.finalize(root, self._unclaim, self._map, slot, token)
        return root.reshape(shape)

    def _unclaim(self, ring: mmap.mmap, slot: int, token: int) -> None:
        claim = self._claimed.get(slot)
        if claim is not None and claim[2] == token:  # this claim, never sent
            del self._claimed[slot]
            _release(ring, slot)

    def owns(self, array: Any) -> bool:
        """Whether ``array`` is a claimed, unsent slot of the current ring (whole)."""
        return self._claim_of(array) is not None

    def _claim_of(self, array: Any) -> tuple[int, int] | None:
        if not self._claimed or not array.flags.c_contiguous or self._map is None:
            return None
        address = array.__array_interface__["data"][0] - self._address
        slot, rest = divmod(address - _HEADER, self.slot_size)
        claimed = self._claimed.get(slot)
        if rest or claimed is None or claimed[:2] != (self.generation, address):
            return None
        return slot, address

    def _sent_in_place(self, array: Any) -> tuple[str, int, int] | None:
        """The address of ``array`` if it is a claimed slot of the current ring, whole."""
        found = self._claim_of(array)
        if found is None:
            return None
        slot, address = found
        del self._claimed[slot]
        array.flags.writeable = False  # the slot is the receiver's now
        return self.name, slot, address

    def in_use(self) -> int:
        """Slots of the current generation the receiver still holds."""
        return 0 if self._map is None else sum(self._map[i] == BUSY for i in range(self.slots))


class RingReader:
    """The receiving side: maps rings by name and hands out arrays viewing slots."""

    def __init__(self) -> None:
        self._maps: dict[str, mmap.mmap] = {}
        self._viewed: set[tuple[str, int]] = set()  # slots with a live view here

    def read(self, name: str, slot: int, offset: int, dtype: str, shape: tuple[int, ...],
             prefix: str = "anodize-") -> Any:
        """An array viewing ``slot`` of ring ``name``; the slot is freed when it is collected.

        ``prefix`` is what the channel's ring names must start with (a sender may
        only point into its own rings).

        Raises:
            ValueError: the address is not a filled slot of one of the sender's rings.
            OSError: the ring does not exist.
        """
        import numpy as np

        if not name.startswith(prefix) or "/" in name:
            raise ValueError(f"ring {name!r} does not belong to this channel")
        ring = self._maps.get(name)
        if ring is None:
            fd = os.open(_path(name), os.O_RDWR)
            try:
                ring = self._maps[name] = mmap.mmap(fd, 0)
            finally:
                os.close(fd)
        slots, slot_size = _GEOMETRY.unpack_from(ring, _HEADER - _GEOMETRY.size)
        dt = np.dtype(dtype)
        count = math.prod(shape)
        if not 0 <= slot < slots or offset != _HEADER + slot * slot_size or \
                count * dt.itemsize > slot_size or ring[slot] != BUSY or (name, slot) in self._viewed:
            raise ValueError(f"slot {slot} at offset {offset} is not a filled slot of ring {name}")
        root = np.frombuffer(ring, dt, count=count, offset=offset)
        self._viewed.add((name, slot))
        weakref.finalize(root, self._release, ring, name, slot)  # when the last view is gone
        return root.reshape(shape)

    def _release(self, ring: mmap.mmap, name: str, slot: int) -> None:
        self._viewed.discard((name, slot))
        _release(ring, slot)


_tokens = itertools.count()


def _release(ring: mmap.mmap, slot: int) -> None:
    if not ring.closed:
        ring[slot] = FREE
