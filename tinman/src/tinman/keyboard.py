"""Driving from the terminal: keys become a gamepad state (``--teleop``).

The group process that runs Joy has no standard input (multiprocessing gives it
/dev/null), so the keyboard is read from the controlling terminal, ``/dev/tty``,
in cbreak mode (keys arrive at once, unechoed). Terminals repeat a held key, so a
key counts as held until ``HOLD`` seconds pass without it.
"""

from __future__ import annotations

import os
import select
import termios
import tty

from .joystick import ANGULAR_AXIS, AXES, BUTTONS, DEADMAN_BUTTON, LINEAR_AXIS

__all__ = ["Keyboard", "KEYS", "TeleopError"]

HOLD = 0.35  # seconds a key press lasts (longer than a terminal's key-repeat delay gap)

# key -> (forward stick, turn stick)
KEYS = {"w": (1.0, 0.0), "s": (-1.0, 0.0), "a": (0.0, 1.0), "d": (0.0, -1.0),
        "q": (1.0, 1.0), "e": (1.0, -1.0)}
SPEED = 0.6  # of full stick: keyboard driving is coarse, keep it gentle


class TeleopError(Exception):
    """There is no terminal to read keys from."""


class Keyboard:
    """The keyboard as a joystick: ``read(t) -> (axes, buttons)`` like ``scripted_joy``."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
        self.sticks = (0.0, 0.0)
        self.pressed_at = -1e9

    @classmethod
    def open(cls) -> Keyboard:
        """Take the controlling terminal.

        Raises:
            TeleopError: the process has no controlling terminal.
        """
        try:
            fd = os.open("/dev/tty", os.O_RDONLY | os.O_NONBLOCK)
        except OSError as error:
            raise TeleopError(f"--teleop needs a terminal to read keys from: {error.strerror}") from None
        return cls(fd)

    def read(self, t: float) -> tuple[tuple[float, ...], tuple[int, ...]]:
        """The sticks after the keys typed since the last read (``t``: seconds since start)."""
        while select.select([self.fd], [], [], 0)[0]:
            try:
                data = os.read(self.fd, 64).decode(errors="ignore").lower()
            except BlockingIOError:
                break
            for key in data:
                if key in KEYS:
                    self.sticks = KEYS[key]
                    self.pressed_at = t
        held = t - self.pressed_at < HOLD
        forward, turn = self.sticks if held else (0.0, 0.0)
        axes = [0.0] * AXES
        axes[LINEAR_AXIS], axes[ANGULAR_AXIS] = forward * SPEED, turn * SPEED
        buttons = [0] * BUTTONS
        buttons[DEADMAN_BUTTON] = int(held)
        return tuple(axes), tuple(buttons)

    def close(self) -> None:
        """Give the terminal its settings back."""
        try:
            termios.tcsetattr(self.fd, termios.TCSADRAIN, self.saved)
        finally:
            os.close(self.fd)
