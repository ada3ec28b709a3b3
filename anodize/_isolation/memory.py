"""Per-group memory bounds: measured, enforced at allocation time, reported honestly.

A group's bound covers what its roles allocate on top of the process's
*baseline* (the interpreter and the modules imported before the roles start),
so ``memory="64MiB"`` means the same whatever numpy or OpenCV cost to import.
Two mechanisms, both where available:

- ``RLIMIT_DATA`` (always on Linux): the kernel refuses to grow the process's
  data segment past baseline + bound, so the allocation itself fails with
  ``MemoryError`` in the role that asked; the group is then stopped as a whole.
- a cgroup memory limit, where the machine has a writable cgroup hierarchy
  (v2 ``memory.max`` or v1 ``memory.limit_in_bytes``): a backstop that also
  counts memory ``RLIMIT_DATA`` does not (shared mappings, kernel buffers); the
  kernel kills the process if it is crossed.

Without a cgroup (none writable, or ``ANODIZE_NO_CGROUP=1``), pages of a tmpfs
file (``/dev/shm``, a ``/tmp`` on tmpfs) belong to the file system, not to any
process: neither ``RLIMIT_DATA`` nor resident memory sees them. The supervisor
then also counts the tmpfs files a group's processes hold open
(:func:`open_tmpfs_bytes`); a tmpfs file written and closed, or left to a process
outside the group, is not bounded, and the report says so. ``RLIMIT_FSIZE`` is
not used: it would bound every file the group writes, on disk too (a recording),
and kill the writer with SIGXFSZ.
"""

from __future__ import annotations

import contextlib
import os
import resource
import signal
import stat
from dataclasses import dataclass

__all__ = ["data_size", "peak_rss", "rss", "limit_data", "Cgroup", "make_cgroup", "remove_stale_cgroups",
           "CGROUP_SLACK", "open_tmpfs_bytes", "tmpfs_devices"]

# On top of baseline + bound: kernel buffers charged to the cgroup, and room for the group to
# report its MemoryError (or the supervisor its measurement) before the kernel kills it.
CGROUP_SLACK = 16 * 2**20


def _status_field(field: str, pid: int | str = "self") -> int | None:
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024  # the kernel writes kB
    except OSError:
        return None
    return None


def data_size(pid: int | str = "self") -> int | None:
    """The process's data segment (``VmData``: heap, anonymous mappings, thread stacks), bytes."""
    return _status_field("VmData", pid)


def peak_rss(pid: int | str = "self") -> int | None:
    """The process's peak resident memory (``VmHWM``), bytes."""
    return _status_field("VmHWM", pid)


def rss(pid: int | str = "self") -> int | None:
    """The process's resident memory now (``VmRSS``), bytes."""
    return _status_field("VmRSS", pid)


def limit_data(limit: int) -> str:
    """Set RLIMIT_DATA (soft and hard: roles cannot raise it again); describe the result."""
    try:
        resource.setrlimit(resource.RLIMIT_DATA, (limit, limit))
    except (ValueError, OSError) as error:
        return f"RLIMIT_DATA refused ({error})"
    return "RLIMIT_DATA"


@dataclass
class Cgroup:
    """A memory cgroup made for one group process (v1 or v2)."""

    path: str
    version: int

    def _file(self, v1: str, v2: str) -> str:
        return os.path.join(self.path, v1 if self.version == 1 else v2)

    def add(self, pid: int) -> None:
        with open(os.path.join(self.path, "cgroup.procs"), "w") as procs:
            procs.write(str(pid))

    def set_limit(self, limit: int) -> None:
        with open(self._file("memory.limit_in_bytes", "memory.max"), "w") as f:
            f.write(str(limit))

    def peak(self) -> int | None:
        try:
            with open(self._file("memory.max_usage_in_bytes", "memory.peak")) as f:
                return int(f.read().split()[0])
        except (OSError, ValueError):
            return None

    def oom_killed(self) -> bool:
        """Whether the kernel killed a process of this cgroup for crossing the limit."""
        name = "memory.oom_control" if self.version == 1 else "memory.events"
        try:
            with open(os.path.join(self.path, name)) as f:
                for line in f:
                    key, _, value = line.partition(" ")
                    if key == "oom_kill" and int(value) > 0:
                        return True
        except (OSError, ValueError):
            pass
        return False

    def kill_all(self) -> None:
        """SIGKILL every process in the cgroup (a child that left the group's process group
        with setsid is still in its cgroup)."""
        kill = os.path.join(self.path, "cgroup.kill")
        if self.version == 2 and os.path.exists(kill):
            with contextlib.suppress(OSError), open(kill, "w") as f:
                f.write("1")
            return
        try:
            with open(os.path.join(self.path, "cgroup.procs")) as procs:
                pids = [int(line) for line in procs if line.strip()]
        except (OSError, ValueError):
            return
        for pid in pids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)

    def remove(self) -> None:
        # OSError: a process still in it, or already gone; the kernel frees it with the last one.
        with contextlib.suppress(OSError):
            os.rmdir(self.path)


def _parents() -> list[tuple[int, str]]:
    """(version, directory) where this process may make memory cgroups."""
    found = []
    for version, mount, own in _memory_hierarchies():
        parent = os.path.join(mount, own.lstrip("/"))
        found.append((version, parent if os.path.isdir(parent) else mount))  # else: a container
    return found


def remove_stale_cgroups() -> int:
    """Remove cgroups ``anodize-<pid>-...`` left by supervisors that were killed."""
    removed = 0
    for _, parent in _parents():
        try:
            names = os.listdir(parent)
        except OSError:
            continue
        for name in names:
            owner = name.split("-")[1] if name.startswith("anodize-") and name.count("-") > 1 else ""
            if owner.isdigit() and not os.path.exists(f"/proc/{owner}"):
                try:
                    os.rmdir(os.path.join(parent, name))
                    removed += 1
                except OSError:
                    pass
    return removed


def make_cgroup(name: str) -> tuple[Cgroup | None, str]:
    """A fresh memory cgroup under this process's own, or None and why not
    (``ANODIZE_NO_CGROUP=1`` makes none: the fallback, on purpose)."""
    if os.environ.get("ANODIZE_NO_CGROUP"):
        return None, "cgroups off: ANODIZE_NO_CGROUP is set"
    for version, parent in _parents():
        path = os.path.join(parent, name)
        try:
            os.mkdir(path)
        except FileExistsError:
            pass
        except OSError as error:
            return None, f"cgroup v{version} not writable ({error.strerror})"
        if version == 2 and not os.path.exists(os.path.join(path, "memory.max")):
            os.rmdir(path)
            return None, "cgroup v2 without the memory controller delegated"
        return Cgroup(path, version), f"cgroup v{version}"
    return None, "no cgroup memory controller mounted"


def _memory_hierarchies() -> list[tuple[int, str, str]]:
    """(version, mount point, this process's cgroup path), memory controller first."""
    own: dict[str, str] = {}
    try:
        with open("/proc/self/cgroup") as f:
            for line in f:
                _, controllers, path = line.rstrip("\n").split(":", 2)
                for controller in controllers.split(",") if controllers else [""]:
                    own[controller] = path
    except OSError:
        return []
    found = []
    try:
        with open("/proc/self/mounts") as f:
            mounts = [line.split() for line in f]
    except OSError:
        return []
    for _, mount, fstype, options, *_ in mounts:
        if fstype == "cgroup" and "memory" in options.split(",") and "memory" in own:
            found.append((1, mount, own["memory"]))
        elif fstype == "cgroup2" and "" in own:
            controllers = os.path.join(mount, "cgroup.controllers")
            try:
                with open(controllers) as c:
                    if "memory" in c.read().split():
                        found.append((2, mount, own[""]))
            except OSError:
                pass
    return found


def tmpfs_devices() -> frozenset[int]:
    """The device numbers of the tmpfs file systems mounted here (read once per run)."""
    found: set[int] = set()
    try:
        with open("/proc/self/mounts") as f:
            mounts = [line.split() for line in f]
    except OSError:
        return frozenset()
    for fields in mounts:
        if len(fields) > 2 and fields[2] == "tmpfs":
            with contextlib.suppress(OSError):
                found.add(os.stat(fields[1].replace("\\040", " ")).st_dev)
    return frozenset(found)


def _mapped(pid: int) -> set[tuple[str, int]]:
    """(device "maj:min", inode) of every file ``pid`` maps: their resident pages are in its VmRSS."""
    found: set[tuple[str, int]] = set()
    with contextlib.suppress(OSError, ValueError), open(f"/proc/{pid}/maps") as maps:
        for line in maps:
            fields = line.split(maxsplit=5)
            if len(fields) > 4 and fields[4] != "0":
                found.add((fields[3], int(fields[4])))
    return found


def open_tmpfs_bytes(pids: list[int], devices: frozenset[int]) -> int:
    """The bytes of the tmpfs files (on ``devices``) that ``pids`` hold open and do not map,
    each file counted once (a mapped one is already in resident memory)."""
    seen: set[tuple[int, int]] = set()
    total = 0
    for pid in pids:
        mapped = _mapped(pid)
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                info = os.stat(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            key = (info.st_dev, info.st_ino)
            if info.st_dev not in devices or not stat.S_ISREG(info.st_mode) or key in seen:
                continue
            seen.add(key)
            if (f"{os.major(info.st_dev):02x}:{os.minor(info.st_dev):02x}", info.st_ino) not in mapped:
                total += info.st_blocks * 512
    return total
