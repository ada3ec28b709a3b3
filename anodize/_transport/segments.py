"""Sealed shared-memory segments: the memory under :mod:`anodize._transport.shm`'s rings.

A segment is a memfd (``memfd_create``): anonymous shared memory, not a file in
``/dev/shm``, so a small ``/dev/shm`` (Docker's 64 MiB) does not limit it and nothing
is left behind when the processes holding it end. Its pages are allocated when it
is made (``posix_fallocate``), so a lack of memory is an error then, never a SIGBUS
later, and it is sealed against shrinking and growing (``F_SEAL_SHRINK``,
``F_SEAL_GROW``, ``F_SEAL_SEAL``): its creator cannot truncate it under a receiver's
mapping either.

A segment reaches the receiving process as a file descriptor passed over a Unix
datagram socket (``SCM_RIGHTS``) to the receiver's :class:`Inbox`, bound before the
run starts. The kernel holds the descriptor while the datagram waits, so a sender
may send its last array and exit at once: the memory lives on until the receiver
has mapped it and let it go. (Opening ``/proc/<sender>/fd/<n>`` instead would fail
once the sender's process has ended.)
"""

from __future__ import annotations

import array
import contextlib
import ctypes
import fcntl
import hashlib
import mmap
import os
import socket
from typing import Any

__all__ = ["PAGE", "SEALS", "SHARED_POPULATED", "create", "verify", "available_memory", "address_of", "protect",
           "Inbox", "hand_over"]

PAGE = mmap.PAGESIZE
SEALS = fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL
_REQUIRED_SEALS = fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW  # what makes a mapping safe from SIGBUS
_NAME_MAX = 200  # bytes of a ring's name in a datagram (memfd names stop at 249)
# A shared mapping whose page-table entries are filled when it is made: the first write or
# read of a slot then takes no page fault (the pages exist already: ``posix_fallocate``).
SHARED_POPULATED = mmap.MAP_SHARED | getattr(mmap, "MAP_POPULATE", 0)


def create(name: str, size: int) -> tuple[int, mmap.mmap]:
    """A sealed memfd of ``size`` bytes, every page allocated, and a read-write mapping of it.

    Raises:
        OSError: no memory for it (ENOMEM, ENOSPC), or memfds are not supported.
    """
    fd = os.memfd_create(name, os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
    try:
        os.ftruncate(fd, size)
        os.posix_fallocate(fd, 0, size)  # every page now: no memory is an error here, not a SIGBUS later
        fcntl.fcntl(fd, fcntl.F_ADD_SEALS, SEALS)
        return fd, mmap.mmap(fd, size, flags=SHARED_POPULATED)
    except BaseException:
        os.close(fd)
        raise


def verify(fd: int, name: str) -> int:
    """Check that ``fd`` is the sealed memfd ``name``; return its size.

    Raises:
        ValueError: it is some other file, or it could still shrink (a mapping of it
            could then raise SIGBUS).
    """
    try:
        target = os.readlink(f"/proc/self/fd/{fd}")
    except OSError:
        target = None  # no /proc: the seals below are what keeps a mapping safe
    if target is not None and target != f"/memfd:{name} (deleted)":
        raise ValueError(f"ring {name} arrived as {target!r}, not as a shared-memory segment of that name")
    if fcntl.fcntl(fd, fcntl.F_GET_SEALS) & _REQUIRED_SEALS != _REQUIRED_SEALS:
        raise ValueError(f"ring {name} is not sealed against shrinking and growing")
    return os.fstat(fd).st_size


def available_memory() -> int | None:
    """Bytes that can still be allocated: the smaller of the machine's ``MemAvailable`` and
    the headroom under this process's memory cgroup limit (None: unknown)."""
    found: list[int] = []
    with contextlib.suppress(OSError, ValueError), open("/proc/meminfo") as meminfo:
        for line in meminfo:
            if line.startswith("MemAvailable:"):
                found.append(int(line.split()[1]) * 1024)
                break
    headroom = _cgroup_headroom()
    if headroom is not None:
        found.append(headroom)
    return min(found) if found else None


def _cgroup_headroom() -> int | None:
    try:
        with open("/proc/self/cgroup") as own:
            lines = own.read().splitlines()
    except OSError:
        return None
    for line in lines:
        _, controllers, path = line.split(":", 2)
        if controllers == "":  # v2
            base, files = os.path.join("/sys/fs/cgroup", path.lstrip("/")), ("memory.max", "memory.current")
        elif "memory" in controllers.split(","):  # v1
            base = os.path.join("/sys/fs/cgroup/memory", path.lstrip("/"))
            files = ("memory.limit_in_bytes", "memory.usage_in_bytes")
        else:
            continue
        try:
            with open(os.path.join(base, files[0])) as limit_file, open(os.path.join(base, files[1])) as used_file:
                limit, used = limit_file.read().strip(), used_file.read().strip()
        except OSError:
            continue
        if limit.isdigit() and used.isdigit() and int(limit) < 2**60:  # "max" or a huge v1 value: none
            return max(0, int(limit) - int(used))
    return None


def address_of(buffer: mmap.mmap) -> int:
    """Where ``buffer`` is mapped in this process (read-only mappings too)."""
    import numpy as np

    address: int = np.frombuffer(buffer, np.uint8, count=1).__array_interface__["data"][0]
    return address


def _mprotect() -> Any:
    try:
        function = ctypes.CDLL(None, use_errno=True).mprotect
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    function.restype = ctypes.c_int
    return function


_MPROTECT = _mprotect()


def protect(address: int, length: int, writable: bool) -> None:
    """Make ``length`` bytes at ``address`` (page-aligned) read-only, or read-write again.

    Raises:
        OSError: the kernel refused.
    """
    if _MPROTECT is None:
        return  # no libc to call: the pages stay writable; numpy's flags still guard them
    prot = mmap.PROT_READ | mmap.PROT_WRITE if writable else mmap.PROT_READ
    if _MPROTECT(address, length, prot) != 0:
        code = ctypes.get_errno()
        raise OSError(code, f"mprotect: {os.strerror(code)}")


def _address(key: str) -> bytes:
    """The abstract socket address of the inbox named ``key`` (hashed: at most 108 bytes)."""
    return b"\0anodize-ring-" + hashlib.sha256(key.encode()).hexdigest()[:40].encode()


class Inbox:
    """Where a receiver gets the segments of one channel's rings (a bound Unix datagram socket).

    Args:
        key: names the channel (the sender derives the same key); unique in the run.

    Raises:
        OSError: the address is taken.
    """

    def __init__(self, key: str) -> None:
        self.socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_NONBLOCK | socket.SOCK_CLOEXEC)
        try:
            self.socket.bind(_address(key))
        except OSError:
            self.socket.close()
            raise
        self._arrived: dict[str, int] = {}  # name -> descriptor, received and not yet taken

    def take(self, name: str) -> int | None:
        """The descriptor of segment ``name`` (the caller closes it), if it arrived."""
        if name not in self._arrived:
            self._receive()
        return self._arrived.pop(name, None)

    def _receive(self) -> None:
        while True:
            try:
                data, fds, _flags, _addr = socket.recv_fds(self.socket, _NAME_MAX, 1, socket.MSG_CMSG_CLOEXEC)
            except BlockingIOError:
                return
            if len(fds) != 1:
                for fd in fds:
                    os.close(fd)
                continue
            name = data.decode(errors="replace")
            if name in self._arrived:  # a second segment by the same name: keep the first
                os.close(fds[0])
            else:
                self._arrived[name] = fds[0]

    def close(self) -> None:
        """Close the socket and every descriptor not taken."""
        self.socket.close()
        for fd in self._arrived.values():
            os.close(fd)
        self._arrived.clear()


def hand_over(sender: socket.socket, key: str, name: str, fd: int) -> bool:
    """Pass segment ``fd`` to the inbox ``key``; False when that inbox is full (try again later).

    Raises:
        ConnectionRefusedError, FileNotFoundError: no inbox by that key (its process ended).
    """
    data = name.encode()
    if len(data) > _NAME_MAX:
        raise ValueError(f"ring name {name!r} is longer than {_NAME_MAX} bytes")
    try:
        # Not socket.send_fds: before Python 3.12 it drops the flags and the address.
        sender.sendmsg([data], [(socket.SOL_SOCKET, socket.SCM_RIGHTS, array.array("i", [fd]))],
                       socket.MSG_DONTWAIT, _address(key))
    except BlockingIOError:
        return False
    return True
