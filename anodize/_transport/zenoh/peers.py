"""Who is there: the liveliness tokens of the run, as one group's session sees them.

Every group declares ``.../alive/<group>/<incarnation>/<host>``, and each end of a
channel ``.../writer|reader/<sender>/<receiver>/<group>/<incarnation>/<id>``. A token
vanishes for everyone when its session closes, dies or is cut off (Zenoh's lease), and
comes back when a router that carried it restarts. The start barrier picks, for each
channel, the one end of the expected group and incarnation (:meth:`Peers.find`); a
failure is a token gone for longer than the run's grace (:meth:`Peers.gone_for`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from .binding import Sample, Session, is_delete, key_of, undeclare, watch_tokens
from .settings import SplitBrainError, ZenohSettings

__all__ = ["Peers"]


class Peers:
    """The run's liveliness tokens that this session sees, kept up to date by Zenoh's thread."""

    def __init__(self, session: Session, settings: ZenohSettings) -> None:
        self.settings = settings
        self.changed = threading.Condition()
        self._alive: set[str] = set()
        self._vanished: dict[str, float] = {}  # key -> when it vanished (monotonic)
        self.listeners: list[Callable[[], None]] = []
        self._subscriber = watch_tokens(session, f"{settings.prefix}/**", self._on_token)

    def _on_token(self, sample: Sample) -> None:
        key = key_of(sample)
        with self.changed:
            if is_delete(sample):
                self._alive.discard(key)
                self._vanished.setdefault(key, time.monotonic())
            else:
                self._alive.add(key)
                self._vanished.pop(key, None)
            self.changed.notify_all()
        for listener in self.listeners:
            listener()

    def find(self, stem: str, channel: str, what: str) -> str | None:
        """The one token under ``stem`` (``.../writer/S/R/<group>/<incarnation>``): its last chunk
        (the end's id, hex), or None while there is none.

        Raises:
            SplitBrainError: several claim it (never guess which one is genuine).
        """
        with self.changed:
            found = sorted(key for key in self._alive if key.startswith(stem + "/"))
        if len(found) > 1:
            raise SplitBrainError(f"{len(found)} Zenoh {what}s on {channel} claim to be the same end: "
                                    + ", ".join(found) + "; is the same run started twice, or is someone forging it?")
        return found[0].rsplit("/", 1)[1] if found else None

    def gone_for(self, key: str) -> float:
        """Seconds the token ``key`` has been gone (0 while it is there)."""
        with self.changed:
            if key in self._alive:
                return 0.0
            since = self._vanished.get(key)
        return 0.0 if since is None else time.monotonic() - since

    def close(self) -> None:
        """Stop watching."""
        undeclare(self._subscriber)
