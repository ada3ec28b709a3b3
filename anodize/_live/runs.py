"""Where the running systems of this host are found: one socket per run, only its user's.

Each ``anodize run`` serves introspection (``anodize ps|status|channels|echo|hz``) on a
UNIX socket named by its run id (``<system>-<pid>.sock``) in a directory of the user's
own: ``$ANODIZE_RUN_DIR`` if set (tests), else ``$XDG_RUNTIME_DIR/anodize``, else
``/tmp/anodize-<uid>``. The directory is made mode 0700 and refused if another user owns
it or can enter it; the socket is mode 0600; and each end checks the other's uid
(``SO_PEERCRED``), so another user cannot reach a run even through a directory made
wrong. A run removes its socket when it ends; a socket left by a run that was killed
(its pid is gone) is removed by the next listing (:func:`running`).
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
import stat
import struct
from pathlib import Path

from ..errors import AnodizeError

__all__ = ["RUN_DIR_ENV", "run_dir", "run_id", "pid_of", "socket_path", "taps_path", "listen", "same_user",
           "peer_uid", "running", "in_use"]

RUN_DIR_ENV = "ANODIZE_RUN_DIR"
_SUFFIX = ".sock"


def run_dir(create: bool = False) -> Path:
    """The directory of this user's runs (made, mode 0700, when ``create``).

    Raises:
        AnodizeError: it is not a directory of this user's that only they can open.
    """
    given = os.environ.get(RUN_DIR_ENV)
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    folder = Path(given) if given else Path(runtime) / "anodize" if runtime else Path(f"/tmp/anodize-{os.getuid()}")
    if create:
        with contextlib.suppress(FileExistsError):
            folder.mkdir(mode=0o700, parents=bool(given or runtime))
    try:
        found = folder.lstat()
    except FileNotFoundError:
        return folder  # no run has made it yet: no run to find
    mode = stat.S_IMODE(found.st_mode)
    if not stat.S_ISDIR(found.st_mode) or found.st_uid != os.getuid() or mode & 0o077:
        raise AnodizeError(f"{folder}: expected a directory of uid {os.getuid()}'s that only it can open "
                           f"(mode 0700), got {'a directory' if stat.S_ISDIR(found.st_mode) else 'no directory'} "
                           f"of uid {found.st_uid}, mode {mode:04o}")
    return folder


def run_id(name: str, pid: int) -> str:
    """A run's id: its system's name and its supervisor's pid, e.g. ``tinman-4242``."""
    cleaned = re.sub(r"[^A-Za-z0-9_.]+", "_", name).strip("._") or "run"
    return f"{cleaned}-{pid}"


def pid_of(run: str) -> int | None:
    """The supervisor's pid a run id names, or None when it names none."""
    tail = run.rpartition("-")[2]
    return int(tail) if tail.isdigit() else None


def socket_path(run: str, folder: Path | None = None) -> Path:
    """Where run ``run`` answers its clients."""
    return (folder or run_dir()) / f"{run}{_SUFFIX}"


def taps_path(run: str, folder: Path | None = None) -> Path:
    """Where run ``run`` takes what its groups tap."""
    return (folder or run_dir()) / f"{run}.taps"


def listen(path: Path) -> socket.socket:
    """A listening socket at ``path``, mode 0600 (a stale one there is replaced)."""
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        listener.bind(str(path))
        path.chmod(0o600)
        listener.listen()
    except OSError:
        listener.close()
        raise
    return listener


def in_use(path: Path) -> bool:
    """Whether a server answers at ``path`` (a run of this process started before, still running)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        try:
            probe.connect(str(path))
        except OSError:
            return False
    return True


def peer_uid(sock: socket.socket) -> int:
    """The uid of the process at the other end of a UNIX socket (``SO_PEERCRED``)."""
    creds = sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    return int(struct.unpack("3i", creds)[1])


def same_user(sock: socket.socket) -> bool:
    """Whether the other end of ``sock`` runs as this process's user."""
    try:
        return peer_uid(sock) == os.getuid()
    except OSError:
        return False


def running(folder: Path | None = None) -> list[str]:
    """The run ids with a socket here whose supervisor lives (sockets of dead pids are removed)."""
    folder = folder or run_dir()
    try:
        names = sorted(entry.name for entry in os.scandir(folder) if entry.name.endswith(_SUFFIX))
    except FileNotFoundError:
        return []
    found = []
    for name in names:
        run = name[:-len(_SUFFIX)]
        pid = pid_of(run)
        if pid is not None and _alive(pid):
            found.append(run)
        else:  # its run was killed before it could remove it
            for stale in (socket_path(run, folder), taps_path(run, folder)):
                with contextlib.suppress(OSError):
                    stale.unlink()
    return found


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process now has the pid: not our run
        return False
    return True
