"""The recorded order of a replayed role's actions, when the role runs several threads.

A role whose parallel branches run in threads of their own (``fork()``) shares state
between them: what one thread sends depends on what another had done by then. A replay
that let each thread run as fast as its inputs allow would interleave them as no run
did. So a replay of such a role takes its threads through the recording's order:

- the *events* are the role's recorded actions that carry the time they happened in the
  run: each message it sent (the time it left) and each reading of its clock (the time
  it was read; ``Endpoint.sleep`` reads the clock as it wakes);
- an event waits for its turn: every event recorded before it has happened. Between two
  of its events a thread runs beside the others, as it did in the run: a thread that
  hands over state just *after* an event (reads its clock, then writes) has usually
  written it before another thread, woken by the event, reads it; one that writes just
  *before* its next event is seen not to have written yet, as in the run;
- an action beyond the recording (a message it has no more of, a clock reading it
  does not hold) waits until every recorded event has happened; a receive of an input
  the recording lost (its recorder fell behind) waits for the events recorded before
  that input was sent (:meth:`Turnstile.take_before`), and the replay ends there.

Receiving is no event (the recording has the time a message was sent, not the time the
role took it): a thread that reads its clock as it takes a message (as a ROS node stamps
what it receives) is ordered exactly; one that does not is ordered by its next event.

A turn that does not come within :data:`PATIENCE` seconds of the last event (a thread
that waits for an event another thread will never reach: the role's code no longer
does what it did in the run) is taken anyway, :attr:`Turnstile.out_of_order` says so,
and from then on no turns are kept (the order is lost: waiting again would only stall).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Hashable, Mapping, Sequence

__all__ = ["Turnstile", "PATIENCE", "BEYOND"]

PATIENCE = 10.0  # seconds a thread waits for its turn with no event happening meanwhile (a thread
                 # between two events may compute for long on a busy machine: a frame, a plan)
BEYOND = None   # the key of an action beyond the recording: it waits until every event has happened


class Turnstile:
    """The turns of a replayed role's threads (see the module docstring).

    Args:
        streams: per stream (a channel out of the role, an endpoint's clock), the recorded
            times of its events, in order (ns since the epoch).
        active: whether turns are kept at all (a role of one thread needs none).
    """

    def __init__(self, streams: Mapping[Hashable, Sequence[int]], active: bool) -> None:
        self.active = active
        self._streams = {key: deque(times) for key, times in streams.items() if times}
        self._turn = threading.Condition()
        self._last_event = time.monotonic()
        self._stopped = False
        self.out_of_order = ""  # the first turn taken without its recorded order, said in a sentence

    def take(self, key: Hashable | None, role: str) -> None:
        """Wait for the turn of stream ``key``'s next event, and take it (the event happens);
        ``key`` :data:`BEYOND`: wait until every recorded event has happened."""
        if not self.active:
            self._pop(key)
            return
        self._wait(lambda: self._ready(key), role, key)

    def _wait(self, ready: Callable[[], bool], role: str, key: Hashable | None = BEYOND) -> None:
        """Wait until ``ready()`` (or patience runs out); then take stream ``key``'s turn, if any."""
        if not self.active:
            return
        began = time.monotonic()  # patience counts from the later of this wait's start and the last turn:
        with self._turn:          # a role that computed for a while before it waits has not lost its turn
            while self.active and not self._stopped and not ready():
                if time.monotonic() - max(self._last_event, began) > PATIENCE:
                    self.out_of_order = self.out_of_order or (
                        f"a thread of {role} ({threading.current_thread().name}) waited {PATIENCE:g} s for its "
                        "recorded turn while no other took one: the role no longer acts as it did in the run, and "
                        "from there its threads may interleave otherwise")
                    self.active = False
                    break
                self._turn.wait(0.05)
            self._pop(key)
            self._last_event = time.monotonic()
            self._turn.notify_all()

    def take_before(self, stamp: int, role: str) -> None:
        """Wait until every event recorded before ``stamp`` (ns since the epoch) has happened: those
        the role did before an input sent at ``stamp`` could have reached it."""
        self._wait(lambda: all(times[0] >= stamp for times in self._streams.values()), role)

    def drop(self, key: Hashable) -> None:
        """Stream ``key`` has no more events (its recorded ones will not happen)."""
        with self._turn:
            self._streams.pop(key, None)
            self._turn.notify_all()

    def stop(self) -> None:
        """The replay ends: nobody waits for a turn any more."""
        with self._turn:
            self._stopped = True
            self._turn.notify_all()

    def _ready(self, key: Hashable | None) -> bool:
        if key is BEYOND:
            return not self._streams
        mine = self._streams.get(key)
        if not mine:
            return True  # no recorded time: nothing to wait for
        return all(mine[0] <= times[0] for times in self._streams.values())

    def _pop(self, key: Hashable | None) -> None:
        if key is BEYOND:
            return
        with self._turn:
            times = self._streams.get(key)
            if times:
                times.popleft()
                if not times:
                    del self._streams[key]
