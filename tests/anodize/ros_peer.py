"""The Fast DDS ROS 2 wire peer of the tests (``tests/anodize/ros_peer/main.cpp``): build it, run it.

:func:`ros_peer_binary` compiles the peer once per machine and source version into
``$XDG_CACHE_HOME/anodize-ros-peer/<hash>/ros_peer`` (``~/.cache`` without XDG_CACHE_HOME), under a
file lock so parallel test sessions build it once; a changed source, compiler or Fast DDS library
gives another hash and so a fresh build. It skips the calling test when g++ or the Fast DDS 2.x
development packages are missing (``scripts/bootstrap`` installs them as root on Debian) and fails
it when the build itself fails: that is a bug in the peer.
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

import pytest

SOURCE_DIR = Path(__file__).resolve().parent / "ros_peer"
BUILD_TIMEOUT = 300.0  # seconds; a build takes a few seconds on two cores
INCLUDE_DIRS = (Path("/usr/include"), Path("/usr/local/include"))
LIBRARY_DIRS = (Path("/usr/lib/x86_64-linux-gnu"), Path("/usr/lib/aarch64-linux-gnu"), Path("/usr/lib"),
                Path("/usr/local/lib"))
INSTALL_HINT = "scripts/bootstrap installs it when run as root on Debian (apt-get install libfastrtps-dev)"


def build_command(source: Path, output: Path) -> list[str]:
    return ["g++", "-std=c++17", "-O1", "-Wall", "-Wextra", "-o", str(output), str(source),
            "-lfastrtps", "-lfastcdr"]


def _find(name: str, directories: Sequence[Path]) -> Path | None:
    """``name`` under the first of ``directories`` (or a multiarch directory below it) that has it."""
    for directory in directories:
        for candidate in (directory / name, *directory.glob(f"*-linux-gnu/{name}")):
            if candidate.exists():
                return candidate
    return None


def _requirements() -> list[Path] | str:
    """What the build reads besides the sources (their sizes and times go into the cache key), or why a
    test must skip."""
    compiler = shutil.which("g++")
    if compiler is None:
        return ("no C++ compiler (g++) for the Fast DDS ROS 2 peer: scripts/bootstrap installs g++ when run as root "
                "on Debian")
    config = _find("fastrtps/config.h", INCLUDE_DIRS)
    if config is None or _find("fastdds/dds/domain/DomainParticipant.hpp", INCLUDE_DIRS) is None:
        return f"Fast DDS (libfastrtps-dev) is not installed: {INSTALL_HINT}"
    major = re.search(r"#define FASTRTPS_VERSION_MAJOR (\d+)", config.read_text())
    if major is None or major.group(1) != "2":
        return f"the ROS 2 peer is written for Fast DDS 2.x; {config} is not 2.x"
    if _find("fastcdr/Cdr.h", INCLUDE_DIRS) is None:
        return f"Fast CDR (libfastcdr-dev) is not installed: {INSTALL_HINT}"
    libraries = [_find(name, LIBRARY_DIRS) for name in ("libfastrtps.so", "libfastcdr.so")]
    found = [library.resolve() for library in libraries if library is not None]
    if len(found) < len(libraries):
        return f"the Fast DDS libraries (libfastrtps.so, libfastcdr.so) are not installed: {INSTALL_HINT}"
    return [Path(compiler).resolve(), config, *found]


def _cache_root() -> Path:
    """``$XDG_CACHE_HOME/anodize-ros-peer``, or a folder of this user under /tmp if that cannot be made."""
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "anodize-ros-peer"
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError:
        root = Path(tempfile.gettempdir()) / f"anodize-ros-peer-{os.getuid()}"
        root.mkdir(exist_ok=True)
    return root


@functools.cache
def _build() -> Path | str:
    """The binary, or why there is none: ``skip:REASON`` (nothing to build it with) or ``fail:REASON``."""
    requirements = _requirements()
    if isinstance(requirements, str):
        return f"skip:{requirements}"
    digest = hashlib.sha256()
    for path in sorted(SOURCE_DIR.iterdir()):
        if path.is_file():
            digest.update(path.name.encode() + b"\0" + path.read_bytes())
    digest.update(" ".join(build_command(Path("main.cpp"), Path("ros_peer"))).encode())
    for path in requirements:
        stat = path.stat()
        digest.update(f"{path}:{stat.st_size}:{stat.st_mtime_ns}".encode())
    folder = _cache_root() / digest.hexdigest()[:16]
    binary = folder / "ros_peer"
    if binary.exists():
        return binary
    with open(folder.parent / f"{folder.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another session may be building the same version
        if binary.exists():
            return binary
        with tempfile.TemporaryDirectory(dir=folder.parent, prefix=f"{folder.name}.build-") as work:
            built = Path(work) / "ros_peer"
            try:
                result = subprocess.run(build_command(SOURCE_DIR / "main.cpp", built), capture_output=True,
                                        text=True, timeout=BUILD_TIMEOUT)
            except subprocess.TimeoutExpired:
                return f"fail:building the Fast DDS ROS 2 peer took more than {BUILD_TIMEOUT:.0f} s"
            if result.returncode != 0:
                return f"fail:building the Fast DDS ROS 2 peer failed:\n{result.stdout}{result.stderr}"
            folder.mkdir(exist_ok=True)
            built.rename(binary)  # atomic: a reader sees no binary or a whole one
    return binary


def ros_peer_binary() -> Path:
    """The built peer; skips the test without a compiler or Fast DDS, fails it when the build fails."""
    result = _build()
    if isinstance(result, Path):
        return result
    kind, _, reason = result.partition(":")
    if kind == "skip":
        pytest.skip(reason)
    pytest.fail(reason, pytrace=False)


def peer_command(command: str, **options: object) -> list[str]:
    """``ros_peer COMMAND --key value ...``; underscores in keys become dashes (``period_ms=50``)."""
    arguments = [str(ros_peer_binary()), command]
    for key, value in options.items():
        arguments += [f"--{key.replace('_', '-')}", str(value)]
    return arguments


def start_peer(command: str, **options: object) -> subprocess.Popen[str]:
    """The peer running ``command`` with stdout and stderr captured (text)."""
    return subprocess.Popen(peer_command(command, **options), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def finish_peer(process: subprocess.Popen[str], timeout: float) -> tuple[int, str, str]:
    """Exit code, stdout and stderr of a started peer, killed if it outlives ``timeout`` seconds."""
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
        err += f"\n(ros_peer killed after {timeout} s)"
    return process.returncode, out, err


def run_peer(command: str, timeout: float, **options: object) -> tuple[int, str, str]:
    """Run the peer to its end (at most ``timeout`` seconds): exit code, stdout, stderr."""
    return finish_peer(start_peer(command, **options), timeout)
