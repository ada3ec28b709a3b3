"""VisOdom's frame dropping: how late a frame is, from capture stamps and VisOdom's own clock."""

from __future__ import annotations

import math

from tinman.roles.perception import STALE_FRAMES, Lateness

PERIOD = 1 / 30
EPOCH = 1_305_031_102.0  # the camera's clock: a replayed sequence's stamps, years ago
BOOT = 5_000.0           # VisOdom's monotonic clock


def test_frames_on_time_are_never_late_whatever_the_clocks_offset() -> None:
    lateness = Lateness()
    for n in range(100):
        jitter = 0.004 * math.sin(n)  # scheduling noise on arrival
        late = lateness(EPOCH + n * PERIOD, BOOT + 0.01 + n * PERIOD + jitter)
        assert late <= 0.008 < STALE_FRAMES * PERIOD


def test_frames_queued_behind_a_slow_tracker_grow_late_and_get_dropped() -> None:
    lateness = Lateness()
    tracked = 1 / 20  # the tracker takes a frame every 50 ms; the camera sends one every 33 ms
    late = [lateness(EPOCH + n * PERIOD, BOOT + n * tracked) for n in range(20)]
    assert late[0] == 0.0 and late == sorted(late)
    assert late[3] < STALE_FRAMES * PERIOD < late[10]


def test_a_quicker_frame_becomes_the_reference() -> None:
    lateness = Lateness()
    assert lateness(EPOCH, BOOT + 0.5) == 0.0                   # the first frame waited at start-up
    assert lateness(EPOCH + PERIOD, BOOT + 0.5 + PERIOD) == 0.0
    assert lateness(EPOCH + 2 * PERIOD, BOOT + 0.01 + 2 * PERIOD) == 0.0  # quicker: the new reference
    assert math.isclose(lateness(EPOCH + 3 * PERIOD, BOOT + 0.21 + 3 * PERIOD), 0.2, abs_tol=1e-6)
