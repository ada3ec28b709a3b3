"""The gamepad mapping (deadzone, deadman, scaling) and the scripted driver's windows."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tinman.joystick import (
    ANGULAR_AXIS,
    DEADMAN_BUTTON,
    DEADZONE,
    JOY_SCRIPT,
    LINEAR_AXIS,
    scripted_joy,
    twist_from_joy,
)
from tinman.messages import Header, Time, joy

RELEASED = (0,) * 8
DEADMAN = tuple(1 if i == DEADMAN_BUTTON else 0 for i in range(8))


def sticks(forward: float = 0.0, turn: float = 0.0) -> tuple[float, ...]:
    axes = [0.0] * 6
    axes[LINEAR_AXIS] = forward
    axes[ANGULAR_AXIS] = turn
    return tuple(axes)


def test_layout_is_the_common_gamepad():
    assert (LINEAR_AXIS, ANGULAR_AXIS, DEADMAN_BUTTON) == (1, 3, 4)


def test_centred_sticks_without_deadman_are_inactive():
    assert twist_from_joy(sticks(), RELEASED) == (0.0, 0.0, False)
    assert twist_from_joy(sticks(0.04, -0.04), RELEASED) == (0.0, 0.0, False)


def test_deadman_alone_takes_over_and_holds_the_robot_still():
    assert twist_from_joy(sticks(), DEADMAN) == (0.0, 0.0, True)


def test_full_sticks_give_the_maximum_speeds():
    assert twist_from_joy(sticks(1.0, 1.0), RELEASED) == (0.5, 1.5, True)
    assert twist_from_joy(sticks(-1.0, -1.0), DEADMAN, max_linear=0.3, max_angular=1.0) == (-0.3, -1.0, True)


def test_other_axes_and_buttons_do_not_drive():
    axes = (0.9, 0.0, 1.0, 0.0, -0.7, 1.0)   # left stick sideways, triggers, right stick forward
    assert twist_from_joy(axes, (1, 1, 1, 1, 0, 1, 1, 1)) == (0.0, 0.0, False)


def test_short_messages_count_as_centred():
    assert twist_from_joy((), ()) == (0.0, 0.0, False)
    assert twist_from_joy((0.0, 0.5), ()) == (0.25, 0.0, True)


@given(forward=st.floats(-1.5, 1.5), turn=st.floats(-1.5, 1.5), deadman=st.booleans())
def test_mapping_is_linear_outside_the_deadzone_and_bounded(forward, turn, deadman):
    v, w, active = twist_from_joy(sticks(forward, turn), DEADMAN if deadman else RELEASED)
    outside = abs(forward) >= DEADZONE or abs(turn) >= DEADZONE
    assert active == (deadman or outside)
    assert abs(v) <= 0.5 and abs(w) <= 1.5
    expected_v = 0.0 if abs(forward) < DEADZONE else max(-1.0, min(1.0, forward)) * 0.5
    expected_w = 0.0 if abs(turn) < DEADZONE else max(-1.0, min(1.0, turn)) * 1.5
    assert (v, w) == (pytest.approx(expected_v), pytest.approx(expected_w))


def test_script_windows_drive_and_idle_elsewhere():
    assert twist_from_joy(*scripted_joy(0.0)) == (0.0, 0.0, False)
    assert twist_from_joy(*scripted_joy(5.99)) == (0.0, 0.0, False)
    v, w, active = twist_from_joy(*scripted_joy(6.5))
    assert active and v > 0.1 and 0.0 < w <= 1.0           # driving while turning left
    assert twist_from_joy(*scripted_joy(7.5)) == (0.0, 0.0, False)   # windows are half open
    v, w, active = twist_from_joy(*scripted_joy(13.5))
    assert active and v == 0.0 and 0.0 < abs(w) <= 1.0     # turning in place, gently
    assert twist_from_joy(*scripted_joy(20.0)) == (0.0, 0.0, False)


def test_script_is_well_formed():
    previous_end = 0.0
    for start, end, axes, buttons in JOY_SCRIPT:
        assert previous_end <= start < end
        assert len(axes) == 6 and len(buttons) == 8
        assert all(-1.0 <= a <= 1.0 for a in axes) and set(buttons) <= {0, 1}
        previous_end = end
    axes, buttons = scripted_joy(100.0)
    assert axes == (0.0,) * 6 and buttons == (0,) * 8


def test_a_custom_script_is_played():
    script = ((1.0, 2.0, sticks(0.2, 0.0), RELEASED),)
    assert scripted_joy(1.5, script) == (sticks(0.2, 0.0), RELEASED)
    assert scripted_joy(6.5, script) == ((0.0,) * 6, (0,) * 8)


def test_a_joy_messages_numpy_arrays_map_to_python_floats() -> None:
    message = joy(Header(stamp=Time(sec=0, nanosec=0), frame_id="joy"), sticks(0.6, 0.3), DEADMAN)
    v, w, active = twist_from_joy(message.axes, message.buttons)
    assert type(v) is float and type(w) is float and active
    assert math.isclose(v, 0.3, rel_tol=1e-6) and math.isclose(w, 0.45, rel_tol=1e-6)


def test_a_foxglove_clients_joy_is_fitted_to_the_gamepad() -> None:
    """A client's Joy (``--foxglove``) may have any length and any floats: Joy sends six
    axes within [-1, 1] (not-a-number centred) and eight buttons 0 or 1."""
    import numpy as np

    from tinman.roles.control import _fitted

    client = joy(Header(stamp=Time(sec=0, nanosec=0), frame_id="foxglove"),
                 np.array([0.5, math.nan, 7.0, -math.inf], np.float32), np.array([0, 3, -1], np.int32))
    assert _fitted(client) == ((0.5, 0.0, 1.0, -1.0, 0.0, 0.0), (0, 1, 1, 0, 0, 0, 0, 0))
    many = joy(Header(stamp=Time(sec=0, nanosec=0), frame_id="foxglove"), np.full(9, 0.25, np.float32),
               np.ones(12, np.int32))
    assert _fitted(many) == ((0.25,) * 6, (1,) * 8)
