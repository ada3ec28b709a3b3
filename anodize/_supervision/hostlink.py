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

Words travel on one DDS topic per run, ``anodize/<run id>/supervisors``, in the run's
partition, reliable and in order per host, JSON in an ``anodize::Frame``. A word is
taken only from a writer whose USER_DATA claims this run (with its token, if the hosts
were given one) and a host of the system other than ours; anything else is dropped and
noted (the same check as the channels, with the same limits: see docs/guide/dds.md).
"""

from __future__ import annotations

import json
import os
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
    ref_of,
    take,
    userdata_of,
    wait_for_acks,
    write,
)
from .._transport.dds.frame import Frame, cdr_sample
from .supervisor import RestartWord, StopWord, Word

__all__ = ["HostLink"]

_TAG = "anodize-supervisor1"


class HostLink:
    """This host's supervisor's end of the run's supervisors topic.

    Args:
        settings: the run's DDS settings (``host`` is this host).
        hosts: every host of the system.
    """

    def __init__(self, settings: DdsSettings, hosts: Collection[str]) -> None:
        self.settings = settings
        self.host = settings.host
        self.hosts = frozenset(hosts)
        self.notes: list[str] = []
        # incarnation -> the groups that start as it (every group starts as 0): a group's
        # channels to groups outside its batch are gone to it.
        self.batches: dict[int, frozenset[str]] = {0: frozenset(settings.host_of)}
        previous = os.environ.get("CYCLONEDDS_URI", "")
        os.environ["CYCLONEDDS_URI"] = ",".join(p for p in (previous, participant_config(settings.lease)) if p)
        self.participant = DomainParticipant(settings.domain)
        topic = Topic(self.participant, topic_name(settings.run_id, "supervisors", "all"), Frame)
        identity = f"{_TAG};{settings.claim_run};{settings.host};{os.getpid()}".encode()
        reliable = (Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepAll,
                    Policy.Userdata(identity), Policy.Partition([settings.partition]))  # the run's alone
        self.writer: DataWriter[Frame] = DataWriter(self.participant, topic, qos=Qos(*reliable))
        self.reader: DataReader[Frame] = DataReader(self.participant, topic, qos=Qos(*reliable))
        self._rejected: set[int] = set()

    def say(self, word: Word) -> None:
        """Tell every other host (best effort: a host that is gone cannot hear it)."""
        if isinstance(word, RestartWord):
            self.batches[word.incarnation] = self.batches.get(word.incarnation, frozenset()) | set(word.groups)
        fields = {"kind": "stop" if isinstance(word, StopWord) else "restart", **word.__dict__}
        body = json.dumps(fields).encode()
        write(ref_of(self.writer), cdr_sample(len(body).to_bytes(4, "little") + body))

    def words(self) -> list[Word]:
        """What the other hosts said since the last call, in the order each said it."""
        taken = take(ref_of(self.reader), ANY_SAMPLE, 64)
        if isinstance(taken, int):
            return []
        words: list[Word] = []
        for data, info in taken:
            if not info.valid_data:
                continue
            host = self._host_of(info.publication_handle)
            if host is None or host == self.settings.host:
                continue  # our own word, or one we may not take (noted once per writer)
            word = _parse(bytes(data[8:]), host)
            if word is None:
                self.notes.append(f"ignored a malformed supervisor word from host {host}")
            else:
                if isinstance(word, RestartWord):
                    self.batches[word.incarnation] = self.batches.get(word.incarnation, frozenset()) | set(word.groups)
                words.append(word)
        return words

    def _host_of(self, handle: int) -> str | None:
        """The host a writer of the supervisors topic speaks for, or None (and a note)."""
        for matched in self.reader.get_matched_publications():
            if instance_handle(matched) != instance_handle(handle):
                continue
            data = self.reader.get_matched_publication_data(matched)
            claim = userdata_of(data.qos if data is not None else None).decode(errors="replace").split(";")
            if len(claim) == 4 and claim[0] == _TAG and claim[1] == self.settings.claim_run and claim[2] in self.hosts:
                return claim[2]
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


def _parse(body: bytes, host: str) -> Word | None:
    try:
        length = int.from_bytes(body[:4], "little")
        fields = json.loads(body[4:4 + length])
        if fields["kind"] == "stop":
            return StopWord(host=host, why=str(fields["why"]))
        if fields["kind"] == "restart":
            return RestartWord(host=host, groups=tuple(str(g) for g in fields["groups"]),
                               incarnation=int(fields["incarnation"]), why=str(fields["why"]))
    except (ValueError, KeyError, TypeError):
        return None
    return None
