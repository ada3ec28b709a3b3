"""Roles of the timed end-to-end runs (tests/anodize/test_timed_end_to_end.py), importable by a
group's process: ONE protocol with a period, a deadline, ``else timeout`` and value constraints,
written as a user writes it, and the roles that keep it, are late, or go out of range."""

from __future__ import annotations

import anodize

# C commands M on a 500 ms beat (every choice of the loop, cmd or stop, keeps it), tells O to
# measure; O's pose reaches M within 1 s; M's ack reaches C within 300 ms, else C is told it timed
# out (and waits on: a slow machine makes a timeout, never an error).
DRIVE = """\
global Drive(C, O, M) =
  mu t. C -> M : {
    cmd(v: float{abs(v) <= 1.5}).
      C -> O : go.
      O -> M : pose(x: float) within 1s.
      M -> C : ack(n: int{n >= 0}) within 300ms else timeout.
      t,
    stop. C -> O : halt. end
  } every 500ms +- 450ms
"""

BEAT = 0.5       # seconds between two choices of C: the period's middle
LATE_BY = 3.0    # how long the late odometer dawdles: far past its 1 s deadline
SLOW_BY = 0.6    # how long the slow motor dawdles: past the ack's 300 ms, inside the beat


def _on_beat(ep: anodize.Endpoint, last: float | None) -> float:
    """Wait for the next beat after ``last`` (on the role's own clock); the time of this one."""
    if last is not None:
        ep.sleep(max(0.0, last + BEAT - ep.now()))
    return ep.now()


def _control(ep: anodize.Endpoint, speeds: tuple[float, ...]) -> int:
    """Commands ``speeds`` on the beat, then stop; how many timeouts it was given."""
    last: float | None = None
    timeouts = 0
    for v in speeds:
        last = _on_beat(ep, last)
        ep.send("M", "cmd", {"v": v})
        ep.send("O", "go")
        while ep.recv("M").label == anodize.TIMEOUT:  # M is slow: the protocol says wait again
            timeouts += 1
    _on_beat(ep, last)
    ep.send("M", "stop")
    ep.send("O", "halt")
    return timeouts


def control(ep: anodize.Endpoint) -> None:
    """Three commands within the limit, on the beat, then stop."""
    _control(ep, (0.5, -1.0, 1.5))


def patient(ep: anodize.Endpoint) -> None:
    """As control, with a slow motor: it must be given the protocol's timeout at least once."""
    if _control(ep, (0.5, 1.0)) == 0:
        raise AssertionError("expected a timeout while the slow motor dawdled, got none")


def reckless(ep: anodize.Endpoint) -> None:
    """Its second command is out of the limit (|v| <= 1.5): refused before it leaves."""
    _control(ep, (0.5, 2.0, 0.5))


def odometer(ep: anodize.Endpoint) -> None:
    """A pose for each go, at once."""
    x = 0.0
    while ep.recv("C").label == "go":
        x += 0.25
        ep.send("M", "pose", {"x": x})


def late_odometer(ep: anodize.Endpoint) -> None:
    """Its second pose comes LATE_BY seconds after its go: M, waiting for it, blames O at the deadline."""
    ep.recv("C")
    ep.send("M", "pose", {"x": 0.0})
    ep.recv("C")
    ep.sleep(LATE_BY)
    ep.send("M", "pose", {"x": 1.0})
    while ep.recv("C").label == "go":
        ep.send("M", "pose", {"x": 2.0})


def motor(ep: anodize.Endpoint) -> None:
    """Takes each command and the pose that follows, and acknowledges them by number."""
    n = 0
    while ep.recv("C").label == "cmd":
        ep.recv("O")
        ep.send("C", "ack", {"n": n})
        n += 1


def slow_motor(ep: anodize.Endpoint) -> None:
    """Acknowledges its first command SLOW_BY seconds late: past the 300 ms, within the beat's 950 ms."""
    n = 0
    while ep.recv("C").label == "cmd":
        ep.recv("O")
        if n == 0:
            ep.sleep(SLOW_BY)
        ep.send("C", "ack", {"n": n})
        n += 1
