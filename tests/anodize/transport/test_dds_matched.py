"""The seam's matched_publications/matched_subscriptions hold when an endpoint matches mid-call.

The binding's own methods ask Cyclone how many endpoints matched, then for that many
handles into an array of that size. An endpoint that matches between the two calls
made the second answer larger than the array: ``IndexError: invalid index``, which
ended a consumer in a CI run (a forger's writer matched while the receiver looked).
"""

from __future__ import annotations

import uuid
from typing import Any

import pytest
from dds_hosts import domain

from anodize._transport.dds.binding import (
    DataReader,
    DataWriter,
    DDSException,
    DomainParticipant,
    Topic,
    delete,
    matched_publications,
    matched_subscriptions,
)
from anodize._transport.dds.frame import Frame


def _entities(writers: int, readers: int) -> tuple[DomainParticipant, Topic[Any], list[DataWriter[Any]],
                                                  list[DataReader[Any]]]:
    participant = DomainParticipant(domain())
    topic = Topic(participant, f"anodize_matched_{uuid.uuid4().hex}", Frame)  # no other test's endpoints
    return (participant, topic, [DataWriter(participant, topic) for _ in range(writers)],
            [DataReader(participant, topic) for _ in range(readers)])


def _match_more_in_between(entity: Any, method: str, more: Any) -> None:
    """Make ``entity``'s count-then-fill C call see ``more()`` endpoints matched after the count."""
    real = getattr(entity, method)
    calls: list[object] = []

    def racing(ref: int, handles: Any, room: int) -> int:
        if handles is not None and not calls:
            calls.append(more())  # the new endpoints match now, between the count and the fill
        result: int = real(ref, handles, room)
        return result

    setattr(entity, method, racing)


@pytest.mark.parametrize("before", [0, 3, 7])
def test_writers_that_match_while_a_reader_lists_them_are_all_listed(before: int) -> None:
    participant, topic, writers, (reader,) = _entities(before, 1)
    _match_more_in_between(reader, "_get_matched_publications",
                           lambda: [DataWriter(participant, topic) for _ in range(12)])
    handles = matched_publications(reader)
    assert len(handles) == before + 12
    assert set(handles) == set(reader.get_matched_publications())  # the same handles as the binding's own
    assert len(writers) == before


def test_readers_that_match_while_a_writer_lists_them_are_all_listed() -> None:
    participant, topic, (writer,), readers = _entities(1, 5)
    _match_more_in_between(writer, "_get_matched_subscriptions",
                           lambda: [DataReader(participant, topic) for _ in range(9)])
    handles = matched_subscriptions(writer)
    assert len(handles) == 5 + 9
    assert set(handles) == set(writer.get_matched_subscriptions())
    assert len(readers) == 5


def test_the_bindings_own_listing_fails_that_way_which_is_why_the_seam_has_its_own() -> None:
    # Shows the race the seam's functions exist for; if a binding release fixes it, this fails
    # and the seam's comment should say so.
    participant, topic, _, (reader,) = _entities(1, 1)
    _match_more_in_between(reader, "_get_matched_publications",
                           lambda: [DataWriter(participant, topic) for _ in range(3)])
    with pytest.raises(IndexError, match="invalid index"):
        reader.get_matched_publications()


def test_listing_a_deleted_readers_writers_raises_a_dds_error_naming_it() -> None:
    _, _, _, (reader,) = _entities(1, 1)
    delete(reader)
    with pytest.raises(DDSException, match="asking for the writers matched by"):
        matched_publications(reader)
