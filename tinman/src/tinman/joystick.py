"""The gamepad: its ``sensor_msgs/Joy`` layout, the scripted driver, and the teleop mapping.

The layout is that of a common XInput gamepad under the ROS ``joy`` driver: six axes
(left stick left/right and forward/back, left trigger, right stick left/right and
forward/back, right trigger) and eight buttons (A, B, X, Y, LB, RB, back, start).
A stick pushed left or forward reads positive.

Nobody holds a real gamepad in a test or a benchmark, so ``scripted_joy`` plays a
fixed script of timed windows instead: the robot is driven by hand for a few seconds
now and then, the rest of the time the planner drives.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["AXES", "BUTTONS", "LINEAR_AXIS", "ANGULAR_AXIS", "DEADMAN_BUTTON", "DEADZONE",
           "JoyWindow", "JOY_SCRIPT", "scripted_joy", "twist_from_joy"]

AXES = 6
BUTTONS = 8
LINEAR_AXIS = 1     # left stick, forward = +1
ANGULAR_AXIS = 3    # right stick, left = +1 (counter-clockwise turn)
DEADMAN_BUTTON = 4  # LB
DEADZONE = 0.05

# (start_s, end_s, axes, buttons): the stick positions held over [start_s, end_s).
JoyWindow = tuple[float, float, tuple[float, ...], tuple[int, ...]]

_IDLE_AXES = (0.0,) * AXES
_IDLE_BUTTONS = (0,) * BUTTONS
_DEADMAN = (0, 0, 0, 0, 1, 0, 0, 0)

# The windows fall where the mission (tinman.mission, DEFAULT_WORLD, seed 0) has open
# floor around the robot, so the hand-driven stretches stay clear of walls and boxes.
JOY_SCRIPT: tuple[JoyWindow, ...] = (
    # A gentle left turn while driving: 0.3 m/s on a 0.5 m/s stick, 0.45 rad/s.
    (6.0, 7.5, (0.0, 0.6, 0.0, 0.3, 0.0, 0.0), _DEADMAN),
    # A short turn in place to the left: 0.75 rad/s for one second.
    (13.0, 14.0, (0.0, 0.0, 0.0, 0.5, 0.0, 0.0), _DEADMAN),
)


def scripted_joy(t: float, script: tuple[JoyWindow, ...] = JOY_SCRIPT) -> tuple[tuple[float, ...], tuple[int, ...]]:
    """The gamepad's state ``t`` seconds into the script.

    Args:
        t: seconds since the script started.
        script: the timed windows; the first window containing ``t`` wins.

    Returns:
        ``(axes, buttons)``: 6 floats and 8 ints; sticks centred and nothing pressed
        outside every window.
    """
    for start, end, axes, buttons in script:
        if start <= t < end:
            return tuple(axes), tuple(buttons)
    return _IDLE_AXES, _IDLE_BUTTONS


def _outside_deadzone(value: float) -> float:
    return 0.0 if abs(value) < DEADZONE else max(-1.0, min(1.0, value))


def twist_from_joy(axes: Sequence[float] | np.ndarray, buttons: Sequence[int] | np.ndarray,
                   max_linear: float = 0.5, max_angular: float = 1.5) -> tuple[float, float, bool]:
    """The Control role's mapping of the gamepad to a velocity command.

    The driver takes over when the deadman button is held or a driving stick is
    pushed past the deadzone; holding the deadman with the sticks centred stops the
    robot. Axes or buttons missing from a short message count as centred/released.

    Args:
        axes, buttons: a ``sensor_msgs/Joy``'s fields (its numpy arrays, or sequences).
        max_linear, max_angular: the speeds of a stick pushed all the way (m/s, rad/s).

    Returns:
        ``(v, w, active)``; ``(0.0, 0.0, False)`` when the driver is not driving.
    """
    forward = _outside_deadzone(float(axes[LINEAR_AXIS])) if len(axes) > LINEAR_AXIS else 0.0
    turn = _outside_deadzone(float(axes[ANGULAR_AXIS])) if len(axes) > ANGULAR_AXIS else 0.0
    deadman = len(buttons) > DEADMAN_BUTTON and bool(buttons[DEADMAN_BUTTON])
    if not deadman and forward == 0.0 and turn == 0.0:
        return 0.0, 0.0, False
    return forward * max_linear, turn * max_angular, True
