"""Bounded reading of input files: a maximum size per kind of file, regular files only.

Every reader of a file a user may be handed (a protocol, a system file, a recording, a
JSON record) goes through here before it parses anything: a device (``/dev/zero``), a
FIFO or a socket is refused before it is read, and a file larger than its kind's limit is
refused with the limit and the environment variable that raises it. The check is made on
the open descriptor, and the read stops one byte past the limit, so a file that grows or
is swapped while it is read cannot get past it.

The limits (docs/guide/threat-model.md):

=================  =========  ==============================
kind               default    raised with
=================  =========  ==============================
protocol           8 MiB      ``ANODIZE_MAX_PROTOCOL_BYTES``
system file        1 MiB      ``ANODIZE_MAX_SYSTEM_FILE_BYTES``
JSON               64 MiB     ``ANODIZE_MAX_JSON_BYTES``
source (lint)      8 MiB      ``ANODIZE_MAX_SOURCE_BYTES``
recording          64 GiB     ``ANODIZE_MAX_RECORDING_BYTES``
rosbag2 metadata   16 MiB     ``ANODIZE_MAX_METADATA_BYTES``
MCAP chunk         256 MiB    ``ANODIZE_MAX_CHUNK_BYTES``
=================  =========  ==============================

An MCAP chunk's limit bounds what one chunk of a recording may expand to
(``anodize._recording.mcap_chunks``), not the size of a file.

A value is a number of bytes, or a size such as ``64MiB``.
"""

from __future__ import annotations

import errno
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

__all__ = ["InputLimit", "InputLimitError", "PROTOCOL", "SYSTEM_FILE", "JSON", "SOURCE", "RECORDING",
           "RECORDING_METADATA", "MCAP_CHUNK", "read_limited", "check_text", "check_file"]


class InputLimitError(OSError):
    """Raised for a file refused before it is parsed: not a regular file, or larger than its limit.

    An ``OSError`` (``errno`` ``EFBIG`` or ``EINVAL``, ``filename`` the path, ``strerror``
    the whole reason), so that every reader that reports a file it cannot read reports it.

    Attributes:
        limit: the limit that was passed, in bytes (0 for a file that is not regular).
    """

    def __init__(self, code: int, reason: str, path: str, limit: int = 0) -> None:
        super().__init__(code, reason, path)
        self.limit = limit

    def __str__(self) -> str:
        return f"{self.filename}: {self.strerror}"


@dataclass(frozen=True)
class InputLimit:
    """The size limit for one kind of file.

    Attributes:
        what: the kind, for messages ("protocol file").
        default: the limit in bytes when the variable is not set.
        variable: the environment variable that sets another limit.
    """

    what: str
    default: int
    variable: str

    def bytes(self) -> int:
        """The limit now: the variable's value when it is set and valid, else the default."""
        given = os.environ.get(self.variable, "").strip()
        match = _SIZE.fullmatch(given)
        if not match:
            return self.default
        number, unit = match.groups()
        return int(number) * _UNITS[(unit or "").lower()]


_SIZE = re.compile(r"(\d{1,20})\s*([KMGT]i?B?|B)?", re.I)
_UNITS = {"": 1, "b": 1, "k": 2**10, "kb": 10**3, "kib": 2**10, "m": 2**20, "mb": 10**6, "mib": 2**20,
          "g": 2**30, "gb": 10**9, "gib": 2**30, "t": 2**40, "tb": 10**12, "tib": 2**40, "ki": 2**10,
          "mi": 2**20, "gi": 2**30, "ti": 2**40}

PROTOCOL = InputLimit("protocol file", 8 * 2**20, "ANODIZE_MAX_PROTOCOL_BYTES")
SYSTEM_FILE = InputLimit("system file", 2**20, "ANODIZE_MAX_SYSTEM_FILE_BYTES")
JSON = InputLimit("JSON file", 64 * 2**20, "ANODIZE_MAX_JSON_BYTES")
SOURCE = InputLimit("Python source file", 8 * 2**20, "ANODIZE_MAX_SOURCE_BYTES")
RECORDING = InputLimit("recording file", 64 * 2**30, "ANODIZE_MAX_RECORDING_BYTES")
RECORDING_METADATA = InputLimit("rosbag2 metadata.yaml", 16 * 2**20, "ANODIZE_MAX_METADATA_BYTES")
MCAP_CHUNK = InputLimit("MCAP chunk", 256 * 2**20, "ANODIZE_MAX_CHUNK_BYTES")


def read_limited(path: str | os.PathLike[str], limit: InputLimit) -> bytes:
    """The bytes of the regular file at ``path``, if it holds at most ``limit.bytes()``.

    The file is opened without blocking (a FIFO with no writer does not hang the open) and
    checked on its descriptor before a byte is read.

    Raises:
        InputLimitError: not a regular file, or larger than the limit.
        OSError: it cannot be opened or read.
    """
    most = limit.bytes()
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        _check(os.fstat(fd), str(path), limit, most)
        os.set_blocking(fd, True)
        chunks: list[bytes] = []
        size = 0
        while size <= most:
            chunk = os.read(fd, min(1 << 20, most + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    finally:
        os.close(fd)
    if size > most:  # it grew while it was read
        raise _too_large(str(path), limit, most)
    return b"".join(chunks)


def check_file(path: str | os.PathLike[str], limit: InputLimit) -> int:
    """Check that ``path`` is a regular file of at most ``limit.bytes()``; return its size.

    For readers that stream a file themselves (recordings).

    Raises:
        InputLimitError: not a regular file, or larger than the limit.
        OSError: it cannot be examined.
    """
    status = Path(path).stat()
    _check(status, str(path), limit, limit.bytes())
    return status.st_size


def _check(status: os.stat_result, shown: str, limit: InputLimit, most: int) -> None:
    if not stat.S_ISREG(status.st_mode):
        raise InputLimitError(errno.EINVAL, f"not a regular file ({_kind(status.st_mode)}); expected a "
                                            f"{limit.what}", shown)
    if status.st_size > most:
        raise _too_large(shown, limit, most)


def _too_large(shown: str, limit: InputLimit, most: int) -> InputLimitError:
    return InputLimitError(errno.EFBIG, f"larger than the {_size(most)} limit for a {limit.what} "
                                        f"(set {limit.variable} to raise it)", shown, most)


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a file"


def _size(number: int) -> str:
    for unit, factor in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if number >= factor and number % factor == 0:
            return f"{number // factor} {unit}"
    return f"{number} bytes"


def check_text(text: str, limit: InputLimit, where: str) -> str:
    """``text`` itself, if its UTF-8 form is at most ``limit.bytes()``: for text that arrives
    inside another file (a protocol embedded in a recording), bounded as if read from its own.

    Raises:
        InputLimitError: larger than the limit.
    """
    most = limit.bytes()
    if len(text) > most or len(text.encode("utf-8", "surrogatepass")) > most:
        raise _too_large(where, limit, most)
    return text
