"""The memory fallback's view of tmpfs: open tmpfs files count, mapped ones are already resident."""

from __future__ import annotations

import mmap
import os
import tempfile
from collections.abc import Iterator
from typing import IO

import pytest

from anodize._isolation.memory import make_cgroup, open_tmpfs_bytes, tmpfs_devices

SIZE = 4 * 2**20


@pytest.fixture
def shm_file() -> Iterator[IO[bytes]]:
    if not os.path.isdir("/dev/shm") or os.stat("/dev/shm").st_dev not in tmpfs_devices():
        pytest.fail("this test needs /dev/shm on tmpfs")
    with tempfile.TemporaryFile(dir="/dev/shm") as file:
        file.write(b"x" * SIZE)
        file.flush()
        yield file


def test_an_open_tmpfs_file_counts(shm_file: IO[bytes]) -> None:
    assert open_tmpfs_bytes([os.getpid()], tmpfs_devices()) >= SIZE


def test_a_mapped_tmpfs_file_is_not_counted_twice(shm_file: IO[bytes]) -> None:
    before = open_tmpfs_bytes([os.getpid()], tmpfs_devices())
    with mmap.mmap(shm_file.fileno(), SIZE):
        assert open_tmpfs_bytes([os.getpid()], tmpfs_devices()) <= before - SIZE


def test_the_fallback_can_be_forced(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ANODIZE_NO_CGROUP", "1")
    cgroup, how = make_cgroup("anodize-test-never")
    assert cgroup is None and "ANODIZE_NO_CGROUP" in how
