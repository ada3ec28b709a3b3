"""The secret key that signs a recording's chain heads (``run --sign-key``, ``verify --key``).

The signature is an HMAC-SHA256 (the ``cryptography`` package is not among anodize's
dependencies, so no public-key signature): whoever checks it holds the same secret, so the
file must be readable by its owner only, as ``ssh`` asks of a private key. Make one with
``head -c 32 /dev/urandom > run.key && chmod 600 run.key``.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import ConfigurationError

__all__ = ["read_signing_key", "KEY_BYTES", "MOST_BYTES"]

KEY_BYTES = 16  # the fewest bytes a key may have (a key of 32 random bytes is what HMAC-SHA256 wants)
MOST_BYTES = 4096  # a key file is small; a larger file is not a key


def read_signing_key(path: str, option: str) -> bytes:
    """The bytes of the key file ``path`` (given with ``option``), checked.

    Raises:
        ConfigurationError: it cannot be read, is not a regular file, is readable by other
            users, or is shorter than :data:`KEY_BYTES` or longer than :data:`MOST_BYTES` bytes.
    """
    shown = f"{option} {path}"
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
    except OSError as error:
        raise ConfigurationError(f"{shown}: cannot open the key file: {error.strerror or error}") from None
    try:
        status = os.fstat(fd)
        if not stat.S_ISREG(status.st_mode):
            raise ConfigurationError(f"{shown}: expected a regular file holding a secret key; found something else")
        if status.st_mode & 0o077:
            raise ConfigurationError(f"{shown}: the key file is readable by other users (mode "
                                     f"{stat.S_IMODE(status.st_mode):o}); expected mode 600 (chmod 600 {path})")
        data = os.read(fd, MOST_BYTES + 1)
    finally:
        os.close(fd)
    if not KEY_BYTES <= len(data) <= MOST_BYTES:
        raise ConfigurationError(f"{shown}: expected a key of {KEY_BYTES} to {MOST_BYTES} bytes; found "
                                 f"{len(data) if len(data) <= MOST_BYTES else 'more'} (make one with "
                                 f"head -c 32 /dev/urandom > {Path(path).name})")
    return data
