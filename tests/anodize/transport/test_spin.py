"""Spin then park (anodize._transport.spin): the setting, the adaptive rule on a fake clock, the
allowance, the never-starve rule, and pipe and ring receivers that take a message while spinning."""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Callable

import pytest

from anodize._transport.spin import (
    BURST,
    FLOOR,
    PROBE_EVERY_MAX,
    SHARE,
    Spinner,
    SpinPolicy,
    describe_spin,
    parse_spin,
    spin_refusal,
)
from anodize.errors import ConfigurationError

US = 1e-6


class FakeClock:
    """Seconds from whole nanoseconds (exact steps) that advance only when a poll is made (each
    poll costs ``step`` nanoseconds) or the test says so."""

    def __init__(self, step: int = 1_000) -> None:
        self.ns = 0
        self.step = step

    def __call__(self) -> float:
        return self.ns / 1e9

    def advance(self, seconds: float) -> None:
        self.ns += round(seconds * 1e9)


def peer(clock: FakeClock, after: float | None) -> tuple[list[int], object]:
    """A ``ready`` that turns true ``after`` seconds from now (None: never); each poll advances
    the fake clock by its step. Returns the poll count (in a list) and the probe."""
    polls = [0]
    due = None if after is None else clock.ns + round(after * 1e9)

    def ready() -> bool:
        polls[0] += 1
        clock.ns += clock.step
        return due is not None and clock.ns >= due

    return polls, ready


def spin_once(spinner: Spinner, clock: FakeClock, after: float | None) -> tuple[bool, int]:
    polls, ready = peer(clock, after)
    return spinner.wait(ready), polls[0]  # type: ignore[arg-type]


# ---- the setting ------------------------------------------------------------------------------
@pytest.mark.parametrize(("given", "nanos"), [
    (None, 0), (False, 0), (0, 0), ("0us", 0), (50, 50_000), ("50us", 50_000), ("50µs", 50_000),
    ("0.2ms", 200_000), ("1ms", 1_000_000), ("750ns", 750), (" 20 us ", 20_000), ("0.001s", 1_000_000)])
def test_a_spin_is_a_duration_as_the_language_writes_them_or_microseconds(given: object, nanos: int) -> None:
    assert parse_spin(given) == nanos


@pytest.mark.parametrize(("given", "problem"), [
    ("50", "expected a duration"), ("fast", "expected a duration"), (True, "expected a duration"),
    (1.5, "expected a duration"), ([50], "expected a duration"), (-5, "expected a duration >= 0"),
    ("2ms", "at most 1ms"), (1001, "at most 1ms"), ("x" * 500, "expected a duration")])
def test_a_spin_that_is_no_duration_or_too_long_is_refused_saying_what_was_expected(
        given: object, problem: str) -> None:
    with pytest.raises(ConfigurationError, match=problem) as caught:
        parse_spin(given)
    assert len(str(caught.value)) < 200  # a long mistake is not repeated whole


def test_a_spin_setting_is_written_back_as_written() -> None:
    assert describe_spin(50_000) == "50us"
    assert describe_spin(750) == "750ns"


# ---- the adaptive rule ------------------------------------------------------------------------
def test_data_within_the_budget_returns_at_once_and_counts_a_wake_saved() -> None:
    clock = FakeClock()
    spinner = SpinPolicy(50 * US, clock).spinner()
    took, polls = spin_once(spinner, clock, after=3 * US)
    assert took and polls == 3  # no polling after the data came
    assert spinner.saved == 1 and spinner.spins == 1
    assert spinner.spun == pytest.approx(3 * US)


def test_a_hit_late_in_the_budget_grows_it_to_twice_the_wait_up_to_the_maximum() -> None:
    clock = FakeClock()
    policy = SpinPolicy(50 * US, clock)
    spinner = policy.spinner()
    spinner.budget = 10 * US
    assert spin_once(spinner, clock, after=8 * US)[0]
    assert spinner.budget == pytest.approx(16 * US)
    assert spin_once(spinner, clock, after=15 * US)[0]
    assert spinner.budget == pytest.approx(30 * US)
    assert spin_once(spinner, clock, after=29 * US)[0]
    assert spinner.budget == pytest.approx(50 * US)  # capped
    assert spin_once(spinner, clock, after=1 * US)[0]
    assert spinner.budget == pytest.approx(50 * US)  # an early hit keeps it


def test_a_caller_s_deadline_shorter_than_the_budget_bounds_the_spin_and_teaches_nothing() -> None:
    clock = FakeClock()
    spinner = SpinPolicy(50 * US, clock).spinner()
    polls, ready = peer(clock, after=None)
    assert not spinner.wait(ready, 5 * US)  # type: ignore[arg-type]
    assert polls[0] == 5  # the receive's timeout, not the 50 us budget
    assert spinner.budget == pytest.approx(50 * US)  # its deadline cut it, not a slow peer
    polls, ready = peer(clock, after=None)
    assert not spinner.wait(ready, 1.0)  # type: ignore[arg-type]
    assert polls[0] == 50 and spinner.budget == pytest.approx(25 * US)


def test_misses_halve_the_budget_down_to_zero_then_it_parks_at_once() -> None:
    clock = FakeClock()
    spinner = SpinPolicy(8 * US, clock).spinner()
    budgets = []
    for _ in range(4):
        took, polls = spin_once(spinner, clock, after=None)
        assert not took and polls >= 1
        budgets.append(spinner.budget)
    assert budgets == pytest.approx([4 * US, 2 * US, 1 * US, 0.0])
    assert spinner.saved == 0 and spinner.spins == 4
    assert spinner.spun == pytest.approx((8 + 4 + 2 + 1) * US)


def test_at_zero_it_probes_with_the_maximum_ever_less_often_while_the_peer_stays_slow() -> None:
    clock = FakeClock()
    spinner = SpinPolicy(4 * US, clock).spinner()
    spinner.budget = 0.0
    probes = []
    for wait in range(300):
        _, polls = spin_once(spinner, clock, after=None)
        if polls:
            probes.append(wait)
    gaps = [b - a for a, b in itertools.pairwise(probes)]
    assert gaps[:6] == [2, 4, 8, 16, 32, 64]
    assert set(gaps[6:]) == {PROBE_EVERY_MAX}  # a slow peer costs at most maximum / 64 a wait


def test_a_probe_that_hits_brings_the_budget_back_and_probing_back_to_every_wait() -> None:
    clock = FakeClock()
    spinner = SpinPolicy(40 * US, clock).spinner()
    spinner.budget = 0.0
    for _ in range(3):  # probes at waits 0, 2: misses
        spin_once(spinner, clock, after=None)
    took = False
    while not took:
        took, _ = spin_once(spinner, clock, after=12 * US)
    assert spinner.budget == pytest.approx(24 * US)
    assert spinner._probe_every == 1


def test_a_peer_slower_than_the_maximum_drives_the_budget_to_zero_and_one_faster_brings_it_back() -> None:
    clock = FakeClock()
    spinner = SpinPolicy(20 * US, clock).spinner()
    for _ in range(10):
        spin_once(spinner, clock, after=500 * US)  # never within the budget
    assert spinner.budget == 0.0
    hits = sum(spin_once(spinner, clock, after=5 * US)[0] for _ in range(20))
    assert hits >= 19 and spinner.budget >= 10 * US


# ---- the allowance: a share of a CPU, whatever the peer ------------------------------------------
def test_spinning_uses_at_most_a_share_of_the_cpu_even_when_it_always_pays() -> None:
    clock = FakeClock(step=1_000)
    policy = SpinPolicy(1000 * US, clock)
    spinner = policy.spinner()
    start = clock()
    for _ in range(2000):  # the peer answers after 900 us each time: spinning always pays
        spin_once(spinner, clock, after=900 * US)
        clock.advance(10 * US)  # the role's own work
    elapsed = clock() - start
    assert policy.spun <= BURST + SHARE * elapsed + 1000 * US
    assert policy.spun >= 0.8 * SHARE * elapsed  # and it does spin as much as allowed
    assert spinner.budget == pytest.approx(1000 * US)  # the cap is not the peer's fault: no shrinking


def test_a_wait_that_finds_less_than_its_budget_in_the_allowance_parks_at_once_and_keeps_the_budget() -> None:
    clock = FakeClock()
    policy = SpinPolicy(100 * US, clock, burst=150 * US)
    spinner = policy.spinner()
    assert spin_once(spinner, clock, after=90 * US) == (True, 90)  # 60 us left, and 22 us refilled
    assert spin_once(spinner, clock, after=None) == (False, 0)  # not a whole spin: no poll at all
    assert spinner.budget == pytest.approx(100 * US)  # the allowance, not a slow peer: no shrinking
    clock.advance(80 * US)  # refills 20 us: 100 us again
    assert spin_once(spinner, clock, after=50 * US) == (True, 50)
    assert SpinPolicy(100 * US, clock, burst=10 * US).burst == 100 * US  # room for one whole spin


def test_the_summary_says_the_cpu_spent_and_the_wakes_saved() -> None:
    clock = FakeClock()
    policy = SpinPolicy(50 * US, clock)
    a, b = policy.spinner(), policy.spinner()
    spin_once(a, clock, after=2 * US)
    spin_once(b, clock, after=None)
    assert policy.summary() == "spinning used 0.1 ms of CPU in 2 waits; 1 wakes saved (50%)"
    assert SpinPolicy(50 * US, clock).summary() == "spinning used 0.0 ms of CPU in 0 waits; 0 wakes saved"


def test_a_policy_needs_a_positive_maximum() -> None:
    with pytest.raises(ValueError, match="> 0"):
        SpinPolicy(0)
    assert FLOOR < 50 * US


# ---- never starve -------------------------------------------------------------------------------
def test_a_fifo_group_may_not_spin_on_a_cpu_another_group_may_use() -> None:
    one, zero = frozenset({1}), frozenset({0})
    assert spin_refusal(None, None, {"other": None}) is None  # ordinary scheduling preempts a spinner
    assert spin_refusal(80, one, {"other": zero}) is None  # a CPU of its own
    assert spin_refusal(80, None, {}) is None  # no other group
    shared = spin_refusal(80, one, {"low": frozenset({0, 1}), "other": zero})
    assert shared is not None and "cpus [1]" in shared and "group low may" in shared and "starve it" in shared
    anywhere = spin_refusal(80, None, {"b": zero, "a": None})
    assert anywhere is not None and "may run on any CPU" in anywhere and "groups a, b" in anywhere
    unpinned_other = spin_refusal(80, one, {"sim": None})
    assert unpinned_other is not None and "sim" in unpinned_other


# ---- the pipe and ring receivers -----------------------------------------------------------------
class _Network:
    def __init__(self) -> None:
        self.failed: dict[str, str] = {}
        self.stopping = False
        self.capacities: dict[tuple[str, str], int] = {}

    def note_failed(self, role: str, cause: str) -> None: ...

    def wait_for_cause(self, role: str, default: str) -> str | None:
        return default


@pytest.mark.parametrize("carrier", ["pipe", "ring"])
def test_a_receiver_takes_a_message_that_arrives_while_it_spins_without_sleeping(carrier: str) -> None:
    # Deterministic: the sender writes only once the receiver is polling, and the spin is long (10 s),
    # so the message always comes while it spins. Between real processes that depends on the machine.
    import multiprocessing

    from anodize._transport.codec import make_codec
    from anodize._transport.process import PipeLinks, channel_ends

    codec = make_codec({}, None, None)
    policy = SpinPolicy(10.0, burst=10.0)
    pair = ("A", "B")
    if carrier == "pipe":
        read_end, write_end = os.pipe()
        receiving, sending = PipeLinks({pair: read_end}, spin=policy), PipeLinks({pair: write_end})
        closers: list[Callable[[], None]] = [lambda: os.close(write_end), lambda: os.close(read_end)]
    else:
        reader_end, writer_end = channel_ends(multiprocessing.get_context("spawn"))
        receiving = PipeLinks.from_ends({pair: reader_end}, spin=policy)
        sending = PipeLinks.from_ends({pair: writer_end})
        closers = [writer_end.close, reader_end.close]
    receiver = receiving.reader(pair, codec, _Network())
    writer = sending.writer(pair, codec, _Network())
    assert receiver.spin is not None and receiver.spin is policy.spinners[0]
    assert (receiver.ring is None) == (carrier == "pipe")
    started = threading.Event()
    probed = receiver._readable if carrier == "pipe" else receiver.ready
    polls = []

    def polled() -> bool:
        polls.append(1)
        started.set()
        return probed()

    if carrier == "pipe":
        receiver._readable = polled  # type: ignore[method-assign]
    else:
        receiver.ready = polled  # type: ignore[method-assign]
    slept = []
    real_poll = receiver._poll

    class Poll:  # records every wait in poll(2) the receiver makes with a timeout
        def poll(self, timeout: float | None = None) -> list[tuple[int, int]]:
            if timeout != 0:
                slept.append(timeout)
            return real_poll.poll(timeout)

    receiver._poll = Poll()  # type: ignore[assignment]
    def send_once_polled() -> None:
        started.wait(10)
        writer.put(("ping", 7))

    sender = threading.Thread(target=send_once_polled)
    sender.start()
    try:
        assert receiver.get(timeout=10) == ("ping", 7)
    finally:
        sender.join(10)
        for close in closers:
            close()
    assert polls and slept == []  # it polled, and took the message without sleeping in poll(2)
    assert (policy.spins, policy.saved) == (1, 1)


def test_without_spin_a_pipe_receiver_has_no_spinner() -> None:
    from anodize._transport.codec import make_codec
    from anodize._transport.process import PipeLinks

    read_end, write_end = os.pipe()
    try:
        receiver = PipeLinks({("A", "B"): read_end}).reader(("A", "B"), make_codec({}, None, None), None)  # type: ignore[arg-type]
        assert receiver.spin is None
    finally:
        os.close(read_end)
        os.close(write_end)
