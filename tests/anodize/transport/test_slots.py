"""Buffers from ``ep.buffer()`` handed over without a page-table change (issue 31, item 2).

The default hand-over makes the buffer, and the array every numpy view of it holds,
read-only; only a view kept from before the send (or a strict buffer) makes the slot's
pages read-only with ``mprotect``. The tests count ``mprotect`` calls (through
``segments.protect``), never time.
"""

from __future__ import annotations

import gc
import secrets
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import slot_roles

import anodize
import sessiontypes
from anodize._transport import segments
from anodize._transport.codec import Codec
from anodize._transport.shm import ArrayRing, RingReader, StaleBufferError

REPO = Path(__file__).resolve().parents[3]
SHAPE = (480, 640, 3)


@pytest.fixture
def prefix() -> str:
    return f"anodize-test{secrets.token_hex(4)}-c"


@pytest.fixture
def protections(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, bool]]:
    """Every ``mprotect`` the rings ask for: (length, writable)."""
    calls: list[tuple[int, bool]] = []
    protect = segments.protect

    def counted(address: int, length: int, writable: bool) -> None:
        calls.append((length, writable))
        protect(address, length, writable)

    monkeypatch.setattr(segments, "protect", counted)
    return calls


def _pair(prefix: str, **options: object) -> tuple[ArrayRing, Codec, Codec]:
    ring = ArrayRing(prefix, slots=2, channel="A->B", **options)  # type: ignore[arg-type]
    return ring, Codec(ring=ring), Codec(read_array=RingReader().read)


def _send(sender: Codec, receiver: Codec, value: object) -> Any:
    return receiver.decode_body(sender.message_frame("frame", value)[4:])[1][1]


def test_a_stream_of_buffers_changes_no_page_protection(prefix: str, protections: list[tuple[int, bool]]) -> None:
    ring, sender, receiver = _pair(prefix)
    for index in range(20):
        image = ring.claim_array(SHAPE, np.uint8)
        image[:] = index
        image[..., 0] = 255 - index  # views made and dropped while filling it
        got = _send(sender, receiver, image)
        assert int(got[0, 0, 0]) == 255 - index and int(got[0, 0, 1]) == index
        del got
    assert protections == []
    assert ring.page_protections == 0 and ring.arrays_sent == 20


def test_a_sent_buffer_and_every_view_made_of_it_later_refuse_writes(prefix: str,
                                                                     protections: list[tuple[int, bool]]) -> None:
    ring, sender, receiver = _pair(prefix)
    image = ring.claim_array(SHAPE, np.uint8)
    image[:] = 9
    got = _send(sender, receiver, image)
    later = [image[1:], image.reshape(-1), image[..., ::3], np.asarray(image), image.base,
             np.asarray(image.base.base)]  # the last: a new array made from the slot's memory itself
    for array in (image, *later):
        assert not array.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            array[...] = 1
    with pytest.raises(ValueError, match="read-only"):
        np.copyto(image, 1)
    with pytest.raises(ValueError, match="cannot set WRITEABLE flag to True"):
        image.flags.writeable = True
    assert int(got.sum()) == 9 * got.size and protections == []


KEPT_VIEWS = {
    "reshaped": lambda image: image.reshape(-1),
    "a slice": lambda image: image[100:, ::2],
    "a view of a view": lambda image: image[1:][1:].view(np.int8),
    "its base": lambda image: image.base,
    "an array made from its memory": lambda image: np.asarray(image.base.base),
}


@pytest.mark.parametrize("make_view", KEPT_VIEWS.values(), ids=KEPT_VIEWS.keys())
def test_a_view_kept_from_before_the_send_makes_that_hand_over_strict(
        prefix: str, protections: list[tuple[int, bool]], make_view: Any) -> None:
    ring, sender, receiver = _pair(prefix)
    image = ring.claim_array(SHAPE, np.uint8)
    kept = make_view(image)  # numpy keeps it writable: only the page protection can stop it
    image[:] = 4
    got = _send(sender, receiver, image)
    assert protections == [(ring.slot_size, False)]
    assert kept is not None and int(got.sum()) == 4 * got.size
    del kept, got, image
    gc.collect()
    again = ring.claim_array(SHAPE, np.uint8)  # the same slot, writable again for the next frame
    again[:] = 5
    assert protections == [(ring.slot_size, False), (ring.slot_size, True)]
    assert int(_send(sender, receiver, again).sum()) == 5 * again.size
    assert len(protections) == 2


def test_a_slot_handed_over_strictly_is_not_filled_again_while_a_view_from_before_the_send_lives(
        prefix: str, protections: list[tuple[int, bool]]) -> None:
    """Filling the slot again would make its pages writable, and the kept view would then
    write into a later frame the receiver reads: the slot waits until the view is gone."""
    ring, sender, receiver = _pair(prefix)
    image = ring.claim_array(SHAPE, np.uint8)
    kept = image[:]
    image[:] = 4
    got = _send(sender, receiver, image)
    del got, image
    gc.collect()  # the receiver is done with the frame: its slot is free again
    frames = []
    for value in (5, 6):  # a buffer and a copy: neither goes into the kept view's slot
        again = ring.claim_array(SHAPE, np.uint8)
        again[:] = value
        frames.append(_send(sender, receiver, again if value == 5 else np.full(SHAPE, value, np.uint8)))
        assert not np.may_share_memory(again, kept)
        del again
    assert protections == [(ring.slot_size, False)]  # the kept view's slot stayed read-only
    assert [int(frame[0, 0, 0]) for frame in frames] == [5, 6]
    del frames, kept
    gc.collect()
    again = ring.claim_array(SHAPE, np.uint8)  # now it may be filled again
    assert protections == [(ring.slot_size, False), (ring.slot_size, True)]
    assert int(again.size) == int(np.prod(SHAPE))


def test_a_buffer_sent_as_a_view_of_itself_still_counts_the_buffer(prefix: str,
                                                                   protections: list[tuple[int, bool]]) -> None:
    ring, sender, receiver = _pair(prefix)
    image = ring.claim_array(SHAPE, np.uint8)
    image[:] = 2
    got = _send(sender, receiver, image.reshape(-1))  # the buffer itself is alive, and seen
    assert protections == [] and not image.flags.writeable
    assert int(got.sum()) == 2 * image.size


def test_a_strict_buffer_is_handed_over_with_its_pages_read_only(prefix: str,
                                                                 protections: list[tuple[int, bool]]) -> None:
    ring, sender, receiver = _pair(prefix)
    image = ring.claim_array(SHAPE, np.uint8, strict=True)
    image[:] = 1
    _send(sender, receiver, image)
    assert protections == [(ring.slot_size, False)]
    strict_ring, sender, receiver = _pair(prefix + "s", strict=True)
    image = strict_ring.claim_array(SHAPE, np.uint8)
    image[:] = 1
    _send(sender, receiver, image)
    assert strict_ring.page_protections == 1


def test_sending_a_buffer_whose_slot_was_filled_again_is_refused_naming_the_channel(prefix: str) -> None:
    ring, sender, receiver = _pair(prefix)
    old = ring.claim_array(SHAPE, np.uint8)
    old[:] = 1
    got = _send(sender, receiver, old)
    resent = _send(sender, receiver, old)  # still the receiver's, unchanged: sent again (copied)
    assert int(resent.sum()) == old.size
    del got, resent
    gc.collect()
    new = ring.claim_array(SHAPE, np.uint8)  # the same slot as ``old``: it now shows the new frame
    new[:] = 2
    assert new.__array_interface__["data"][0] == old.__array_interface__["data"][0]
    message = (r"^cannot send an array from ep\.buffer\(\) made for channel A->B: it was sent already and its "
               r"shared-memory slot 0 has been filled again since \(claim 1, now 2\); expected a fresh "
               r"ep\.buffer\(\) for each frame, got a stale one$")
    for stale in (old, old[10:], old.reshape(-1), old[:1, :1]):  # a view under 64 KiB too (it would go inline)
        with pytest.raises(StaleBufferError, match=message) as caught:
            sender.message_frame("frame", stale)
        assert (caught.value.channel, caught.value.slot, caught.value.claim, caught.value.current) == \
            ("A->B", 0, 1, 2)
    assert ring.owns(new) and int(_send(sender, receiver, new).sum()) == 2 * new.size
    assert anodize.StaleBufferError is StaleBufferError and isinstance(caught.value, anodize.AnodizeError)


def test_a_received_array_forwarded_on_is_never_stale(prefix: str) -> None:
    ring, sender, receiver = _pair(prefix)
    _, forward, far_end = _pair(prefix + "f")
    image = ring.claim_array(SHAPE, np.uint8)
    image[:] = 3
    got = _send(sender, receiver, image)
    assert int(_send(forward, far_end, got).sum()) == 3 * image.size


def test_a_forged_slot_offset_or_size_is_refused(prefix: str) -> None:
    ring, _, _ = _pair(prefix)
    name, slot, offset = ring.write(np.ones(SHAPE, np.uint8)) or ("", 0, 0)
    reader = RingReader()
    forged = [(name, slot, offset + 4096, "|u1", SHAPE),  # inside the slot, not at its start
              (name, slot + 1, offset, "|u1", SHAPE),  # another slot's number with this slot's offset
              (name, slot, offset, "<f8", SHAPE),  # eight times the slot's size
              (name, 2**32 - 1, offset, "|u1", (1,))]
    for address in forged:
        with pytest.raises(ValueError, match=r"^slot \d+ at offset \d+ is not a filled slot of ring "):
            reader.read(*address)
    assert int(reader.read(name, slot, offset, "|u1", SHAPE).sum()) == int(np.prod(SHAPE))


def _child(body: str) -> subprocess.CompletedProcess[str]:
    code = textwrap.dedent("""
        import resource, secrets
        import numpy as np
        from anodize._transport.codec import Codec
        from anodize._transport.shm import ArrayRing, RingReader
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        ring = ArrayRing(f"anodize-child{secrets.token_hex(4)}-c", slots=2)
        sender, receiver = Codec(ring=ring), Codec(read_array=RingReader().read)
    """) + textwrap.dedent(body)
    return subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120,
                          check=False)


def test_a_write_through_a_view_kept_from_before_the_send_faults_in_the_sender() -> None:
    result = _child("""
        image = ring.claim_array((480, 640, 3), np.uint8)
        kept = image.reshape(-1)
        got = receiver.decode_body(sender.message_frame("frame", image)[4:])[1][1]
        print("sent", flush=True)
        kept[0] = 1
        print("written", flush=True)
    """)
    assert (result.returncode, result.stdout) == (-11, "sent\n"), result.stderr


def test_a_strict_buffer_faults_a_write_through_a_memoryview_taken_before_the_send() -> None:
    result = _child("""
        image = ring.claim_array((480, 640, 3), np.uint8, strict=True)
        raw = memoryview(image).cast("B")
        got = receiver.decode_body(sender.message_frame("frame", image)[4:])[1][1]
        print("sent", flush=True)
        raw[0] = 1
        print("written", flush=True)
    """)
    assert (result.returncode, result.stdout) == (-11, "sent\n"), result.stderr


UNSEEN = {
    "a memoryview": "memoryview(image).cast('B')",
    "as_strided": "np.lib.stride_tricks.as_strided(image).reshape(-1)",
    "a numpy subclass's view": "image.view(np.recarray).reshape(-1)",
}


@pytest.mark.parametrize("escape", UNSEEN.values(), ids=UNSEEN.keys())
def test_what_the_default_hand_over_does_not_see_writes_through(escape: str) -> None:
    # Said plainly in the docs: these, taken before the send, are not caught (ask for strict=True).
    result = _child(f"""
        image = ring.claim_array((480, 640, 3), np.uint8)
        raw = {escape}
        got = receiver.decode_body(sender.message_frame("frame", image)[4:])[1][1]
        raw[0] = 7
        print(int(got[0, 0, 0]), ring.page_protections)
    """)
    assert (result.returncode, result.stdout) == (0, "7 0\n"), result.stderr


@pytest.mark.slow
def test_between_processes_sending_a_stale_buffer_fails_its_role_and_nothing_arrives() -> None:
    protocol = sessiontypes.loads("""
        type Frame = "slot_roles:Frame"
        global Stale(A, B) = A -> B : frame(Frame). B -> A : dropped. A -> B : again(Frame)
    """, "test_slots.proto").globals["Stale"]
    system = anodize.System(protocol, transport=anodize.Processes())
    system.group("a").role("A", slot_roles.stale_source)
    system.group("b").role("B", slot_roles.stale_sink)
    report = system.run(timeout=60)
    assert report.roles["B"].status == "done", report.summary()
    assert str(report.roles["A"].error) == (
        "StaleBufferError: cannot send an array from ep.buffer() made for channel A->B: it was sent already and "
        "its shared-memory slot 0 has been filled again since (claim 1, now 2); expected a fresh ep.buffer() for "
        "each frame, got a stale one")
