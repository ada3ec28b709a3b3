"""The pickle guard on its own: what travels pickled, the scan, and the unpickler that loads one class.

The codec's tests (test_codec.py) cover the guard as a frame meets it; these call it directly.
"""

from __future__ import annotations

import collections
import enum
import pickle
import pickletools
from dataclasses import dataclass

import numpy as np
import pytest
from budget import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from anodize._transport.pickle_guard import (
    PICKLE_PROTOCOL,
    PickleRefusedError,
    scan_pickle,
    travels_pickled,
    unpickle,
)


class Plain:
    def __init__(self, value: object = None) -> None:
        self.value = value

    def __eq__(self, other: object) -> bool:
        return type(other) is Plain and other.value == self.value

    __hash__ = None  # type: ignore[assignment]


class Stranger:
    pass


@dataclass
class Fields:
    value: int


class Colour(enum.Enum):
    RED = 1


def test_only_classes_the_codec_does_not_encode_itself_travel_pickled() -> None:
    assert travels_pickled(Plain) and travels_pickled(Colour)
    for own in (Fields, int, str, bytes, dict, list, tuple, type(None), np.ndarray, np.float32):
        assert not travels_pickled(own), own


@pytest.mark.parametrize("value", [None, 7, "text", [1, (2, 3)], {"a": {1, 2}}, 2**300, b"\0" * 10])
def test_a_plain_instance_passes_the_scan_and_comes_back_equal(value: object) -> None:
    data = pickle.dumps(Plain(value), protocol=PICKLE_PROTOCOL)
    assert scan_pickle(data, Plain) is None
    assert unpickle(data, Plain) == Plain(value)


def test_a_pickle_of_another_class_is_refused_by_the_scan_and_by_the_unpickler() -> None:
    data = pickle.dumps(Stranger(), protocol=PICKLE_PROTOCOL)
    assert scan_pickle(data, Plain) == f"it refers to {__name__}.Stranger, not to the payload's class"
    with pytest.raises(PickleRefusedError, match=r"refers to .*Stranger, which the protocol does not name$"):
        unpickle(data, Plain)  # the unpickler's own fence, should the scan ever be skipped


@pytest.mark.parametrize(("data", "reason"), [
    (pickle.dumps([1, 2], protocol=PICKLE_PROTOCOL), "the pickle does not hold exactly one instance"),
    (pickle.dumps(collections.OrderedDict(), protocol=PICKLE_PROTOCOL), "it refers to collections.OrderedDict"),
    (pickle.dumps(Plain(), protocol=1), "pickle protocol 0 or 1"),
    (b"\x80\x05" + b"cos\nsystem\n.", "it refers to os.system"),
    (b"\x80\x05N" + b"r" + (2**27).to_bytes(4, "little") + b".", "memo index 134217728 out of sequence"),
    (pickle.dumps(Plain(), protocol=PICKLE_PROTOCOL) + b"x", "1 bytes after the pickle's end"),
    (b"\x80\x05\x8c", "malformed pickle"),
])
def test_the_scan_names_what_it_refuses(data: bytes, reason: str) -> None:
    found = scan_pickle(data, Plain)
    assert found is not None and found.startswith(reason), found


@settings(max_examples=examples(200), deadline=None)
@given(st.binary(max_size=64))
def test_whatever_bytes_the_scan_passes_unpickle_into_one_instance(tail: bytes) -> None:
    data = b"\x80\x05" + tail
    if scan_pickle(data, Plain) is None:
        assert type(unpickle(data, Plain)) is Plain


def test_every_opcode_of_an_ordinary_pickle_is_one_the_scan_knows() -> None:
    data = pickletools.optimize(pickle.dumps(Plain({"k": [1.5, None, True]}), protocol=PICKLE_PROTOCOL))
    assert scan_pickle(data, Plain) is None
