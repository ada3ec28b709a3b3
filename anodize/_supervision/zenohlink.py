"""What the supervisors of one Zenoh run, each on its own host, tell each other.

The same words as on DDS (:mod:`.hostwords`; :mod:`.hostlink` says what they are for), on
one key per run, ``<prefix>/supervisors`` (``prefix`` is ``anodize/<run id>/<token
digest>``): a reliable publisher (congestion control Block, so nothing is dropped; Zenoh
keeps a publisher's samples in order) and a subscriber there. The session is the caller's,
already open; this module imports ``zenoh`` only through the transport's binding.

Each word's attachment says who said it and proves it knows the run's claim (run id and
token): ``anodize-supervisor2;<host>;<supervisor id>;<mac>``, the mac an HMAC-SHA256 keyed by
the claim over the word's bytes, host and supervisor id. The claim itself never travels (the
key prefix holds only a digest of the token), so a program that can subscribe to the run's
keys cannot learn it there and speak -- when the hosts were given a token
(``ANODIZE_ZENOH_TOKEN``): without one the claim is the run id, which every key shows, and
the run's report says so. A word whose mac does not match the run's claim, or
whose host is not one of the system's, is dropped and noted once per writer; our own words
come back to our subscriber and are dropped by our supervisor id. As on DDS, someone who
records words can replay them (a private network or Zenoh's TLS and access control keep
them out).
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import threading
from collections import deque
from collections.abc import Collection
from typing import Any

from .._transport.zenoh.binding import attachment_of, payload_of, publisher, subscribe, undeclare
from .hostwords import Batches, encode, parse
from .words import Word

__all__ = ["ZenohHostLink"]

_REPORTED = 8  # writers of rejected words named in the notes, at most (a forger may make up any number)
_TAG = "anodize-supervisor2"
_KEPT = 4096  # words heard and not yet taken, at most (the supervisor takes them every 0.1 s)


class ZenohHostLink:
    """This host's supervisor's end of the run's supervisors key.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it, after :meth:`close`).
        prefix: the run's key prefix, ``anodize/<run id>/<token digest>``.
        claim: the run's claim (run id and token), known to the run's hosts alone.
        host: this host.
        hosts: every host of the system.
    """

    def __init__(self, session: Any, prefix: str, claim: str, host: str, hosts: Collection[str]) -> None:
        self.host = host
        self.hosts = frozenset(hosts)
        self.supervisor = secrets.token_hex(4)
        self.notes: list[str] = []
        self.batches = Batches(())
        self._key = claim.encode()
        self._heard: deque[tuple[bytes, bytes]] = deque(maxlen=_KEPT)
        self._lock = threading.Lock()
        self._rejected: set[str] = set()
        self._publisher = publisher(session, f"{prefix}/supervisors")
        self._subscriber = subscribe(session, f"{prefix}/supervisors", self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        """On one of Zenoh's threads: keep the word for :meth:`words`."""
        with self._lock:
            self._heard.append((payload_of(sample), attachment_of(sample)))

    def say(self, word: Word) -> None:
        """Tell every other host (best effort: a host that is gone cannot hear it)."""
        self.batches.hear(word)
        body = encode(word)
        attachment = f"{_TAG};{self.host};{self.supervisor};{self._mac(body, self.host, self.supervisor)}"
        self._publisher.put(body, attachment=attachment.encode())

    def words(self) -> list[Word]:
        """What the other hosts said since the last call, in the order each said it."""
        with self._lock:
            heard, self._heard = list(self._heard), deque(maxlen=_KEPT)
        words: list[Word] = []
        for body, attachment in heard:
            who = self._who(body, attachment)
            if who is None or who[1] == self.supervisor:
                continue  # our own word, or one we may not take (noted once per writer)
            word = parse(body, *who)
            if word is None:
                self.notes.append(f"ignored a malformed supervisor word from host {who[0]}")
            else:
                self.batches.hear(word)
                words.append(word)
        return words

    def _who(self, body: bytes, attachment: bytes) -> tuple[str, str] | None:
        """The host and supervisor that said ``body``, if it proves it knows the run's claim; else None
        (and a note, once per writer)."""
        fields = attachment.decode(errors="replace").split(";")
        if (len(fields) == 4 and fields[0] == _TAG and fields[1] in self.hosts
                and hmac.compare_digest(fields[3].encode(), self._mac(body, fields[1], fields[2]).encode())):
            return fields[1], fields[2]
        writer = ";".join(fields[:3])[:200]
        if writer not in self._rejected and len(self._rejected) < _REPORTED:  # the network may make up any number
            self._rejected.add(writer)
            why = ("it is not one of the system's hosts" if len(fields) == 4 and fields[0] == _TAG
                   and fields[1] not in self.hosts else "it does not prove it knows the run's claim")
            self.notes.append(f"rejected supervisor words on Zenoh from {writer!r} ({why}); only the run's "
                              "hosts may speak there")
        return None

    def _mac(self, body: bytes, host: str, supervisor: str) -> str:
        message = body + b"\0" + host.encode() + b"\0" + supervisor.encode()
        return hmac.new(self._key, message, hashlib.sha256).hexdigest()[:32]

    def close(self) -> None:
        """Stop saying and hearing (the session stays the caller's)."""
        undeclare(self._subscriber)
        undeclare(self._publisher)
