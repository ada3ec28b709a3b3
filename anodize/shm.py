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

import glob
import mmap
import os
import tempfile
import time
import weakref
from collections.abc import Callable
from typing import Any

__all__ = ["ArrayRing", "RingReader", "remove_run_segments", "segment_dir"]

FREE, BUSY = 0, 1
_HEADER = 4096  # the slot states live in the first page
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
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
    return len(paths)


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
        self._claimed: dict[int, tuple[int, int]] = {}  # slot -> (generation, offset), not yet sent
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
        nbytes = dt.itemsize
        for n in shape:
            nbytes *= n
        if nbytes > self.slot_size:
            self._grow(nbytes)
        assert self._map is not None
        slot = self._claim()
        offset = _HEADER + slot * self.slot_size
        root = np.frombuffer(self._map, dt, count=nbytes // dt.itemsize, offset=offset)
        self._claimed[slot] = (self.generation, offset)
        weakref.finalize(root, self._unclaim, self._map, slot, self.generation)
        return root.reshape(shape)

    def _unclaim(self, ring: mmap.mmap, slot: int, generation: int) -> None:
        if self._claimed.get(slot, (None,))[0] == generation:  # claimed, never sent
            del self._claimed[slot]
            _release(ring, slot)

    def _sent_in_place(self, array: Any) -> tuple[str, int, int] | None:
        """The address of ``array`` if it is a claimed slot of the current ring, whole."""
        if not self._claimed or not array.flags.c_contiguous or self._map is None:
            return None
        address = array.__array_interface__["data"][0] - self._address
        slot, rest = divmod(address - _HEADER, self.slot_size)
        claimed = self._claimed.get(slot)
        if rest or claimed != (self.generation, address):
            return None
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

    def read(self, name: str, slot: int, offset: int, dtype: str, shape: tuple[int, ...]) -> Any:
        """An array viewing ``slot`` of ring ``name``; the slot is freed when it is collected.

        Raises:
            ValueError: the address does not lie inside the ring.
            OSError: the ring does not exist.
        """
        import numpy as np

        ring = self._maps.get(name)
        if ring is None:
            if "/" in name or not name.startswith("anodize-"):
                raise ValueError(f"not a ring name: {name!r}")
            fd = os.open(_path(name), os.O_RDWR)
            try:
                ring = self._maps[name] = mmap.mmap(fd, 0)
            finally:
                os.close(fd)
        dt = np.dtype(dtype)
        count = 1
        for n in shape:
            count *= n
        if not 0 <= slot < _HEADER or ring[slot] != BUSY or offset < _HEADER or \
                offset + count * dt.itemsize > len(ring):
            raise ValueError(f"slot {slot} at offset {offset} is not a filled slot of ring {name}")
        root = np.frombuffer(ring, dt, count=count, offset=offset)
        weakref.finalize(root, _release, ring, slot)  # fires when the last view is gone
        return root.reshape(shape)


def _release(ring: mmap.mmap, slot: int) -> None:
    if not ring.closed:
        ring[slot] = FREE
