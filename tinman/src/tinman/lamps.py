"""How bright the realistic room's lamps are over time: a slow drift, and a failing tube.

Every lamp drifts slowly (a sine of +-6 % with a period of 6 to 14 s: a dimmer, a
supply that sags when something else switches on). The last lamp's tube is
failing: now and then (0.25 times a second on average) it flickers for 0.2 to
0.8 s, switching at 7 Hz between full brightness and 50 to 80 % of it, so
consecutive frames at 30 fps see the room lit differently. A gain of 1 is the
brightness the textures were lit with; the renderer relights a frame with the
gains (:meth:`tinman.render.RoomRenderer.render`). Mains ripple (100 or 120 Hz)
is left out: the camera's 20 ms exposure averages it away.

The gains are a function of time and the seed alone, so a frame's lighting can be
recomputed (a sequence on disk, a live run) and does not depend on the frame rate.
"""

from __future__ import annotations

import numpy as np

__all__ = ["GAIN_RANGE", "FlickeringLamps"]

GAIN_RANGE = (0.45, 1.1)  # every gain lies within these bounds
_DRIFT = 0.06
_DRIFT_PERIOD = (6.0, 14.0)   # seconds
_FLICKER_RATE = 0.25          # episodes per second, on the failing lamp
_FLICKER_LENGTH = (0.2, 0.8)  # seconds
_FLICKER_DEPTH = (0.5, 0.8)   # brightness while the tube is out
_FLICKER_HZ = 7.0
_HORIZON = 3600.0             # seconds of episodes drawn; the pattern repeats after


class FlickeringLamps:
    """The brightness of ``count`` lamps over time, drawn once from ``seed``.

    Args:
        count: how many lamps (the last one is the failing one).
        seed: the pattern's seed.

    Raises:
        ValueError: ``count`` is less than 1.
    """

    def __init__(self, count: int, seed: int = 0) -> None:
        if count < 1:
            raise ValueError(f"expected at least one lamp, got {count}")
        self.count = count
        rng = np.random.default_rng([seed, 11])
        self._periods = rng.uniform(*_DRIFT_PERIOD, count)
        self._phases = rng.uniform(0.0, 2.0 * np.pi, count)
        episodes = rng.poisson(_FLICKER_RATE * _HORIZON)
        self._starts = np.sort(rng.uniform(0.0, _HORIZON, episodes))
        self._ends = self._starts + rng.uniform(*_FLICKER_LENGTH, episodes)
        self._depths = rng.uniform(*_FLICKER_DEPTH, episodes)

    def gains(self, t: float) -> np.ndarray:
        """Each lamp's brightness at ``t`` seconds (float64, ``(count,)``, within :data:`GAIN_RANGE`)."""
        t = float(t) % _HORIZON
        gains = 1.0 + _DRIFT * np.sin(2.0 * np.pi * t / self._periods + self._phases)
        episode = int(np.searchsorted(self._starts, t, side="right")) - 1
        if episode >= 0 and t < self._ends[episode]:
            # A square wave: the tube is out for the first half of each cycle.
            out = ((t - self._starts[episode]) * _FLICKER_HZ) % 1.0 < 0.5
            if out:
                gains[-1] *= self._depths[episode]
        return np.clip(gains, *GAIN_RANGE)

    def flickering(self, t: float) -> bool:
        """Whether the failing lamp is in a flickering episode at ``t``."""
        t = float(t) % _HORIZON
        episode = int(np.searchsorted(self._starts, t, side="right")) - 1
        return episode >= 0 and t < self._ends[episode]
