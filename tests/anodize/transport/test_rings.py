"""Shared-memory rings under attack (issue 11): held slots, shrunk segments, writes after send."""

from __future__ import annotations

import fcntl
import gc
import os
import secrets
import socket
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import ring_roles as roles

import anodize
import sessiontypes
from anodize import MemoryBoundError
from anodize._transport.bridge import BridgeQueue
from anodize._transport.codec import Codec
from anodize._transport.segments import Inbox, hand_over
from anodize._transport.shm import ArrayRing, RingAllocationError, RingFullError, RingReader

REPO = Path(__file__).resolve().parents[3]

PROTOCOLS = sessiontypes.loads("""
type Frame = "ring_roles:Frame"
global Frames(A, B) = mu t. A -> B : {frame(Frame). t, fin}
global Truncate(A, B) = A -> B : frame(Frame). A -> B : truncated(str)
global Rewrite(A, B) = A -> B : frame(Frame). A -> B : checked(str). A -> B : after(int)
global One(A, B) = A -> B : frame(Frame)
global Flood(A, B, C) = (mu t. A -> B : {blob(bytes). t, fin} || C -> B : hello)
""", "test_rings.proto").globals


def run(global_name: str, groups: dict[str, dict[str, object]], timeout: float = 60) -> anodize.RunReport:
    system = anodize.System(PROTOCOLS[global_name], transport=anodize.Processes())
    for name, spec in groups.items():
        spec = dict(spec)
        placed = spec.pop("roles")
        group = system.group(name, **spec)  # type: ignore[arg-type]
        for role, function in placed.items():  # type: ignore[attr-defined]
            group.role(role, function)
    return system.run(timeout=timeout)


@pytest.fixture
def prefix() -> str:
    return f"anodize-test{secrets.token_hex(4)}-c"


# ---- 1. a held slot never deadlocks a session ----------------------------------------------------
@pytest.mark.slow
def test_a_receiver_keeping_more_frames_alive_than_the_ring_has_slots_gets_them_all() -> None:
    report = run("Frames", {"a": {"roles": {"A": roles.hoard_source}},
                            "b": {"roles": {"B": roles.hoarding_sink}}}, timeout=30)
    assert report.ok, report.summary()
    assert report.messages["A->B"] == roles.KEPT + 1


@pytest.mark.slow
def test_a_receiver_keeping_a_window_of_eight_frames_streams_on() -> None:
    report = run("Frames", {"a": {"roles": {"A": roles.window_source}},
                            "b": {"roles": {"B": roles.window_sink}}}, timeout=30)
    assert report.ok, report.summary()
    assert report.messages["A->B"] == roles.WINDOW_FRAMES + 1


@pytest.mark.slow
def test_frames_leaked_into_reference_cycles_with_the_collector_off_do_not_stall_the_sender() -> None:
    report = run("Frames", {"a": {"roles": {"A": roles.hoard_source}},
                            "b": {"roles": {"B": roles.cycle_sink}}}, timeout=30)
    assert report.ok, report.summary()
    assert report.messages["A->B"] == roles.KEPT + 1


def _gives_up_after(seconds: float) -> Callable[[], str | None]:
    """A ``peer_gone`` that ends a sender's wait for a slot after ``seconds`` (so no test waits for ever)."""
    deadline = time.monotonic() + seconds
    return lambda: "test deadline: no slot came back" if time.monotonic() > deadline else None


def test_with_every_slot_held_an_array_goes_inline_and_a_buffer_is_an_ordinary_array(prefix: str) -> None:
    ring = ArrayRing(prefix, slots=2, peer_gone=_gives_up_after(10.0))
    sender, receiver = Codec(ring=ring), Codec(read_array=RingReader().read)
    held = [receiver.decode_body(sender.message_frame("a", np.full(100_000, i))[4:])[1][1] for i in range(2)]
    assert ring.in_use() == 2
    frame = sender.message_frame("a", np.full(100_000, 7))
    assert len(frame) > 800_000  # copied into the frame: no slot was free
    got = receiver.decode_body(frame[4:])[1][1]
    assert got.base is None and int(got.sum()) == 700_000  # a private copy, the receiver's own memory
    spare = ring.claim_array((100_000,), np.float64)
    assert type(spare) is np.ndarray and spare.base is None and not ring.owns(spare)
    assert [int(h[0]) for h in held] == [0, 1]


def test_an_array_too_big_for_a_frame_waits_for_a_slot_then_fails_naming_what_the_receiver_holds(prefix: str
                                                                                                  ) -> None:
    ring = ArrayRing(prefix, slots=1, channel="A->B", inline_max=100_000, patience=0.2)
    sender, receiver = Codec(ring=ring), Codec(read_array=RingReader().read)
    held = receiver.decode_body(sender.message_frame("a", np.ones(200_000, np.uint8))[4:])[1][1]
    with pytest.raises(RingFullError, match=(
            r"^cannot send a 0\.2 MiB array on channel A->B: the receiver holds all 1 slots of its shared-memory "
            r"ring \(0\.2 MiB each: arrays it received and still keeps alive\), none came back within 0\.2 s, "
            r"and an array over 0\.1 MiB cannot be copied into a frame instead$")) as caught:
        sender.message_frame("a", np.ones(200_000, np.uint8))
    assert (caught.value.slots, caught.value.nbytes, caught.value.channel) == (1, 200_000, "A->B")
    del held
    gc.collect()
    assert sender.message_frame("a", np.ones(200_000, np.uint8))  # the slot came back: sent


def test_a_sender_waits_for_slots_of_arrays_still_on_their_way(prefix: str) -> None:
    ring = ArrayRing(prefix, slots=1, peer_gone=_gives_up_after(30.0))
    reader = RingReader()
    first = ring.write(np.ones(100_000))
    assert first is not None

    def take_then_drop() -> None:  # the receiver, behind: it takes the array later and drops it at once
        view = reader.read(*first, "<f8", (100_000,))
        del view

    late = threading.Timer(0.2, take_then_drop)
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1.0)  # the sender must not look between the take and the drop
    try:
        late.start()
        second = ring.write(np.ones(100_000))  # waits: the first array is in flight, not held
    finally:
        sys.setswitchinterval(interval)
    late.join(timeout=30)
    assert second is not None and second[1] == first[1]


# ---- 2. no SIGBUS ---------------------------------------------------------------------------------
@pytest.mark.slow
def test_a_sender_cannot_shrink_its_ring_under_its_receiver() -> None:
    report = run("Truncate", {"a": {"roles": {"A": roles.truncating_source}},
                              "b": {"roles": {"B": roles.unharmed_sink}}})
    assert report.ok, report.summary()


def test_a_ring_is_a_sealed_memfd_not_a_file_in_dev_shm(prefix: str) -> None:
    ring = ArrayRing(prefix, slots=2)
    name, _, _ = ring.write(np.ones(100_000)) or ("", 0, 0)
    fd = next(int(n) for n in os.listdir("/proc/self/fd")
              if os.readlink(f"/proc/self/fd/{n}") == f"/memfd:{name} (deleted)")
    seals = fcntl.fcntl(fd, fcntl.F_GET_SEALS)
    assert seals & (fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL) == \
        fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL
    with pytest.raises(PermissionError):
        os.ftruncate(fd, 4096)
    assert not list(Path("/dev/shm").glob(f"{prefix}*"))


def test_a_ring_too_big_for_the_memory_left_is_a_clear_error_when_it_is_made(prefix: str) -> None:
    ring = ArrayRing(prefix, channel="A->B")
    with pytest.raises(RingAllocationError, match=(
            r"^cannot allocate a 8192\.0 GiB shared-memory ring for channel A->B \(8 slots of 1024\.0 GiB\): "
            r"only \d+\.\d (MiB|GiB) of memory is available$")):
        ring.claim_array((2**40,), np.uint8)


def test_a_ring_the_kernel_refuses_is_a_clear_error_not_a_sigbus_later() -> None:
    # A file size limit makes the kernel refuse the ring (as a full memory would) in a child process.
    code = textwrap.dedent("""
        import resource, signal
        import numpy as np
        from anodize._transport.shm import ArrayRing, RingAllocationError
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (2**20, 2**20))
        try:
            ArrayRing("anodize-fsize-c", channel="A->B").write(np.zeros(2**21, np.uint8))
        except RingAllocationError as error:
            print(error)
    """)
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120,
                            check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout == ("cannot allocate a 16.0 MiB shared-memory ring for channel A->B (8 slots of 2.0 MiB): "
                             "[Errno 27] File too large\n")


def test_a_reader_refuses_a_handed_over_file_that_could_shrink(prefix: str, tmp_path: Path) -> None:
    key = f"{prefix}-inbox"
    reader = RingReader(key)
    sender = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    unsealed = os.memfd_create(f"{prefix}-1-x")
    os.ftruncate(unsealed, 8192)
    regular = os.open(tmp_path / "ring", os.O_RDWR | os.O_CREAT)
    os.ftruncate(regular, 8192)
    assert hand_over(sender, key, f"{prefix}-1-x", unsealed) and hand_over(sender, key, f"{prefix}-2-y", regular)
    with pytest.raises(ValueError, match=r"^ring .*-1-x is not sealed against shrinking and growing$"):
        reader.read(f"{prefix}-1-x", 0, 4096, "|u1", (1,), prefix=prefix)
    with pytest.raises(ValueError, match=r"^ring .*-2-y arrived as '.*/ring', not as a shared-memory segment"):
        reader.read(f"{prefix}-2-y", 0, 4096, "|u1", (1,), prefix=prefix)
    with pytest.raises(ValueError, match=r"^ring .*-3-z was never handed over to this receiver$"):
        reader.read(f"{prefix}-3-z", 0, 4096, "|u1", (1,), prefix=prefix)
    for fd in (unsealed, regular):
        os.close(fd)
    sender.close()


def test_an_inbox_keeps_a_segment_alive_after_its_sender_let_go(prefix: str) -> None:
    reader = RingReader(f"{prefix}-inbox")
    ring = ArrayRing(prefix, slots=2, inbox=f"{prefix}-inbox")
    address = ring.write(np.full(100_000, 3.0))
    assert address is not None
    del ring
    gc.collect()  # the sender's descriptor and mapping are gone; the datagram holds the memory
    assert float(reader.read(*address, "<f8", (100_000,)).sum()) == 300_000.0
    inbox = Inbox(f"{prefix}-other")
    assert inbox.take(address[0]) is None
    inbox.close()


@pytest.mark.slow
def test_a_sender_that_ends_right_after_sending_leaves_its_array_readable() -> None:
    report = run("One", {"a": {"roles": {"A": roles.one_frame_source}},
                         "b": {"roles": {"B": roles.late_sink}}})
    assert report.ok, report.summary()


# ---- 3. bridge threads buffer within a bound ------------------------------------------------------
@pytest.mark.slow
def test_a_bounded_receiver_with_parallel_branches_takes_a_fast_stream_slowly() -> None:
    report = run("Flood", {"a": {"roles": {"A": roles.blob_source}},
                           "b": {"memory": "64MiB", "roles": {"B": roles.slow_parallel_sink}},
                           "c": {"roles": {"C": roles.hello_sender}}}, timeout=120)
    assert report.ok, report.summary()
    assert not isinstance(report.groups["b"].error, MemoryBoundError)
    assert report.messages["A->B"] == roles.BLOBS + 1


def test_a_full_bridge_queue_makes_its_pump_wait_but_never_a_signal() -> None:
    queue = BridgeQueue(messages=2, budget=1000)
    queue.put_message(("a", 1), 600)
    pumped = threading.Thread(target=queue.put_message, args=(("b", 2), 600))
    pumped.start()
    pumped.join(timeout=0.2)
    assert pumped.is_alive()  # over the byte budget: it waits
    queue.put("a signal")  # never waits
    assert queue.get(timeout=5) == ("a", 1)
    pumped.join(timeout=30)
    assert not pumped.is_alive()
    assert [queue.get(timeout=5), queue.get(timeout=5)] == ["a signal", ("b", 2)]
    assert queue.empty()


# ---- 4. zero copy, without writes after send ------------------------------------------------------
@pytest.mark.slow
def test_a_sender_rewriting_a_sent_slot_faults_in_its_own_process_and_the_receiver_keeps_its_data() -> None:
    report = run("Rewrite", {"a": {"roles": {"A": roles.rewriting_source}},
                             "b": {"roles": {"B": roles.watching_sink}}})
    assert "SIGSEGV" in str(report.groups["a"].error), report.summary()
    assert report.roles["B"].status == "done", report.summary()


@pytest.mark.slow
def test_a_received_array_leads_nowhere_near_the_ring() -> None:
    report = run("One", {"a": {"roles": {"A": roles.one_frame_source}},
                         "b": {"roles": {"B": roles.inspecting_sink}}})
    assert report.ok, report.summary()


def test_arrays_on_both_sides_of_a_ring_are_read_only_once_sent_and_stay_so(prefix: str) -> None:
    ring = ArrayRing(prefix, slots=2)
    sender, receiver = Codec(ring=ring), Codec(read_array=RingReader().read)
    image = ring.claim_array((480, 640, 3), np.uint8)
    image[:] = 9
    got = receiver.decode_body(sender.message_frame("image", image)[4:])[1][1]
    for array in (image, got, got[1:, ::2]):
        assert not array.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            array[0, 0, 0] = 1
        with pytest.raises(ValueError, match="cannot set WRITEABLE flag to True"):
            array.flags.writeable = True
    assert roles.reachable_buffers(got) == [] and roles.reachable_buffers(got[1:, ::2]) == []
    assert int(got.sum()) == 9 * got.size
    # The slot, reclaimed after the receiver let it go, is writable again for the next array.
    del got, array
    gc.collect()
    again = [ring.claim_array((480, 640, 3), np.uint8) for _ in range(2)]
    for claimed in again:
        claimed[:] = 1
    assert ring.in_use() == 2 and all(ring.owns(claimed) for claimed in again)


def test_an_old_received_array_still_reads_a_sender_that_is_gone(prefix: str) -> None:
    ring = ArrayRing(prefix, slots=2)
    frame = Codec(ring=ring).message_frame("a", np.full(100_000, 5.0))
    got = Codec(read_array=RingReader().read).decode_body(frame[4:])[1][1]
    del ring
    gc.collect()
    assert float(got.sum()) == 500_000.0


def test_a_peer_failure_ends_the_wait_for_a_ring_inbox(prefix: str) -> None:
    ring = ArrayRing(prefix, slots=2, inbox=f"{prefix}-nobody", peer_gone=lambda: "B failed")
    with pytest.raises(BrokenPipeError, match=r"^B failed$"):
        ring.write(np.ones(100_000))
