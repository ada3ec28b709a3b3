"""What the supervisors of one DDS run, each on its own host, tell each other.

A system whose groups run on several hosts has one supervisor per host (``anodize
run --host``). Each applies the failure policies of its own groups; the policies
that reach beyond a group need the others:

- ``stop-system`` (and the timeout, and Ctrl-C): the host that stops its groups
  says so, and every other host stops its groups too;
- ``restart``: the host of the failed group works out the restart set over the
  whole system (the failed group and every group connected to it through channels
  whose policy is ``restart`` too, wherever it runs), names the set's new
  incarnation, and says so; every host restarts its members of the set as that
  incarnation. The new incarnations meet at a start barrier that accepts only
  writers of that incarnation, and a channel to a group outside the set is gone to
  them, as with ``Processes``.

Words (:mod:`.hostwords`) travel on one DDS topic per run, ``anodize/<run id>/supervisors``, in the run's
partition, reliable and in order per host, JSON in an ``anodize::Frame``. A word is
taken only from a writer whose USER_DATA claims this run (with its token, if the hosts
were given one) and a host of the system, and names the supervisor (a random id drawn at
its start) that said it; anything else is dropped and noted (the same check as the
channels, with the same limits: see docs/guide/dds.md). Our own words come back to our
reader and are dropped by that id, not by the host: a second supervisor that claims our
host is heard (that is a split brain, :mod:`.hostview`).
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Collection

from .._transport.dds import DdsSettings, instance_handle, participant_config, topic_name
from .._transport.dds.binding import (
    ANY_SAMPLE,
    DataReader,
    DataWriter,
    DomainParticipant,
    Policy,
    Qos,
    Topic,
    delete,
    duration,
    matched_publications,
    ref_of,
    take,
    userdata_of,
    wait_for_acks,
    write,
)
from .._transport.dds.frame import Frame, cdr_sample
from .hostwords import Batches, encode, parse
from .words import Word

__all__ = ["HostLink"]

_TAG = "anodize-supervisor2"


class HostLink:
    """This host's supervisor's end of the run's supervisors topic.

    Args:
        settings: the run's DDS settings (``host`` is this host).
        hosts: every host of the system.
    """

    def __init__(self, settings: DdsSettings, hosts: Collection[str]) -> None:
        self.settings = settings
        self.host = settings.host
        self.supervisor = secrets.token_hex(4)
        self.hosts = frozenset(hosts)
        self.notes: list[str] = []
        self.batches = Batches(settings.host_of)
        previous = os.environ.get("CYCLONEDDS_URI", "")
        os.environ["CYCLONEDDS_URI"] = ",".join(p for p in (previous, participant_config(settings.lease)) if p)
        self.participant = DomainParticipant(settings.domain)
        topic = Topic(self.participant, topic_name(settings.run_id, "supervisors", "all"), Frame)
        identity = f"{_TAG};{settings.claim_run};{settings.host};{os.getpid()};{self.supervisor}".encode()
        reliable = (Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepAll,
                    Policy.Userdata(identity), Policy.Partition([settings.partition]))  # the run's alone
        self.writer: DataWriter[Frame] = DataWriter(self.participant, topic, qos=Qos(*reliable))
        self.reader: DataReader[Frame] = DataReader(self.participant, topic, qos=Qos(*reliable))
        self._rejected: set[int] = set()
        # Writers already checked: a supervisor's last words (its farewell) are often taken after its
        # writer has left the domain, when the matched publications no longer say who it was.
        self._known: dict[int, tuple[str, str]] = {}

    def say(self, word: Word) -> None:
        """Tell every other host (best effort: a host that is gone cannot hear it)."""
        self.batches.hear(word)
        write(ref_of(self.writer), cdr_sample(encode(word)))

    def words(self) -> list[Word]:
        """What the other hosts said since the last call, in the order each said it."""
        taken = take(ref_of(self.reader), ANY_SAMPLE, 64)
        if isinstance(taken, int):
            return []
        words: list[Word] = []
        for data, info in taken:
            if not info.valid_data:
                continue
            who = self._host_of(info.publication_handle)
            if who is None or who[1] == self.supervisor:
                continue  # our own word, or one we may not take (noted once per writer)
            host, supervisor = who
            word = parse(bytes(data[8:]), host, supervisor)
            if word is None:
                self.notes.append(f"ignored a malformed supervisor word from host {host}")
            else:
                self.batches.hear(word)
                words.append(word)
        return words

    def _host_of(self, handle: int) -> tuple[str, str] | None:
        """The host and supervisor a writer of the supervisors topic speaks for, or None (and a note)."""
        if instance_handle(handle) in self._known:
            return self._known[instance_handle(handle)]
        for matched in matched_publications(self.reader):
            if instance_handle(matched) != instance_handle(handle):
                continue
            data = self.reader.get_matched_publication_data(matched)
            claim = userdata_of(data.qos if data is not None else None).decode(errors="replace").split(";")
            if len(claim) == 5 and claim[0] == _TAG and claim[1] == self.settings.claim_run and claim[2] in self.hosts:
                self._known[instance_handle(handle)] = (claim[2], claim[4])
                return claim[2], claim[4]
            if instance_handle(handle) not in self._rejected:
                self._rejected.add(instance_handle(handle))
                self.notes.append(f"rejected supervisor words from DDS writer {data.key if data else handle} "
                                  f"(it claims {';'.join(claim)!r}); only the run's hosts may speak there")
            return None
        return None  # gone already: its words cannot be attributed

    def close(self) -> None:
        """Let what was said reach the others (bounded), then leave the domain."""
        try:
            wait_for_acks(self.writer, 1.0)
        finally:
            delete(self.participant)

