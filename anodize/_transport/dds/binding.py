"""The seam to the Cyclone DDS binding: the one module that imports ``cyclonedds`` or touches its privates.

The rest of anodize uses the binding only through the names declared here (pyzmq's
``zmq/backend/select.py`` is the model: one place says which calls the rest may use).
Most are the binding's public API, re-exported; the few that reach past it are
functions here, so that a new binding release that moves them breaks this module only:

- :func:`write` and :func:`take` are the binding's C calls (``cyclonedds._clayer``)
  that write and take raw CDR bytes, skipping its element-by-element encoding (a
  900 KB array costs one copy). They take an entity's :func:`ref_of`, looked up once
  when a lane is built, never per message.
- :func:`delete` deletes an entity now (the binding deletes on garbage collection,
  too late for a reader whose writer must see it unmatched).
- :func:`wait_for_acks` waits for a writer's acknowledgements (the binding's own method
  raises AttributeError when they do not all come in time: it looks for
  ``Exception.DDS_RETCODE_TIMEOUT``).
- :func:`matched_publications` and :func:`matched_subscriptions` list what an
  endpoint has matched (the binding's own methods ask Cyclone for the count, then for
  that many handles into an array of that size; an endpoint that matches between the
  two calls makes Cyclone's second answer larger than the array, and the binding
  raises ``IndexError: invalid index``).

``cyclonedds`` is imported when this module is, through :func:`anodize._extras.import_extra`:
only a DDS run, the ROS wire or a supervisor of several hosts imports it, and
without the ``anodize[dds]`` extra that import raises
:class:`~anodize.errors.MissingExtraError`. The test ``test_binding_seam.py`` fails if
any other module under ``anodize/`` names the binding's private API.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..._extras import import_extra

if TYPE_CHECKING:  # the same names, for the type checker (which has the binding installed)
    from cyclonedds._clayer import ddspy_take as take
    from cyclonedds._clayer import ddspy_write as write
    from cyclonedds.core import DDSException, InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.idl import IdlStruct
    from cyclonedds.idl import types as idl_types
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration
else:
    _FEATURE = "the DDS transport"
    _clayer = import_extra("cyclonedds._clayer", "dds", _FEATURE)
    _core = import_extra("cyclonedds.core", "dds", _FEATURE)
    _idl = import_extra("cyclonedds.idl", "dds", _FEATURE)
    write = _clayer.ddspy_write
    take = _clayer.ddspy_take
    DDSException, InstanceState, Policy, Qos = _core.DDSException, _core.InstanceState, _core.Policy, _core.Qos
    ReadCondition, SampleState, ViewState, WaitSet = (_core.ReadCondition, _core.SampleState, _core.ViewState,
                                                      _core.WaitSet)
    DomainParticipant = import_extra("cyclonedds.domain", "dds", _FEATURE).DomainParticipant
    IdlStruct, idl_types = _idl.IdlStruct, _idl.types
    DataWriter = import_extra("cyclonedds.pub", "dds", _FEATURE).DataWriter
    DataReader = import_extra("cyclonedds.sub", "dds", _FEATURE).DataReader
    Topic = import_extra("cyclonedds.topic", "dds", _FEATURE).Topic
    duration = import_extra("cyclonedds.util", "dds", _FEATURE).duration

__all__ = ["write", "take", "ref_of", "delete", "wait_for_acks", "userdata_of", "ANY_SAMPLE", "RETCODE_TIMEOUT",
           "XCDR1", "matched_publications", "matched_subscriptions",
           "DDSException", "Policy", "Qos", "ReadCondition", "WaitSet", "DomainParticipant", "IdlStruct",
           "idl_types", "DataWriter", "DataReader", "Topic", "duration"]

_HANDLE = ctypes.c_int64  # dds_instance_handle_t, as the binding declares it in its C calls
RETCODE_TIMEOUT = -10  # DDS_RETCODE_TIMEOUT, from write: no room within the writer's blocking time
ANY_SAMPLE = SampleState.Any | ViewState.Any | InstanceState.Any  # what take() takes: every sample
# ROS 2 publishes plain CDR (XCDR1): its readers do not accept a writer that offers only XCDR2.
XCDR1 = (Policy.DataRepresentation(use_cdrv0_representation=True),)


def ref_of(entity: DataWriter[Any] | DataReader[Any]) -> int:
    """The C handle of a writer or reader, for :func:`write` and :func:`take` (look it up once)."""
    ref: int = entity._ref
    return ref


def delete(entity: DataWriter[Any] | DataReader[Any] | DomainParticipant) -> None:
    """Delete ``entity`` now: its peers see it unmatched at once, not when Python collects it."""
    entity.__del__()


def wait_for_acks(writer: DataWriter[Any], seconds: float) -> bool:
    """Wait up to ``seconds`` until every matched reliable reader has acknowledged what ``writer``
    wrote: True if they all did, False if the time ran out.

    Raises:
        DDSException: the writer is gone or the call failed.
    """
    ret: int = writer._wait_for_acks(writer._ref, duration(seconds=seconds))
    if ret == 0:
        return True
    if ret == RETCODE_TIMEOUT:
        return False
    raise DDSException(ret, f"waiting for acknowledgements of {writer!r}")


def userdata_of(qos: Qos | None) -> bytes:
    """The USER_DATA an endpoint's QoS carries (empty if none)."""
    if qos is None:
        return b""
    try:
        policy = qos[Policy.Userdata]
    except (KeyError, TypeError):
        return b""
    data = getattr(policy, "data", b"")
    return data if isinstance(data, bytes) else b""


def matched_publications(reader: DataReader[Any]) -> list[int]:
    """The instance handles of the writers ``reader`` has matched now.

    Raises:
        DDSException: the reader is gone or the call failed.
    """
    return _matched(reader._get_matched_publications, reader, "writers")


def matched_subscriptions(writer: DataWriter[Any]) -> list[int]:
    """The instance handles of the readers ``writer`` has matched now.

    Raises:
        DDSException: the writer is gone or the call failed.
    """
    return _matched(writer._get_matched_subscriptions, writer, "readers")


def _matched(call: Callable[[int, Any, int], int], entity: DataReader[Any] | DataWriter[Any],
             what: str) -> list[int]:
    """Ask Cyclone for the matched handles with room for as many as it says there are: it
    returns how many there are, which is more than the room when some matched since it
    was last asked; then ask again with room for them all."""
    room = 8
    while True:
        handles = (_HANDLE * room)()
        count = call(ref_of(entity), ctypes.cast(handles, ctypes.POINTER(_HANDLE)), room)
        if count < 0:
            raise DDSException(count, f"asking for the {what} matched by {entity!r}")
        if count <= room:
            return list(handles[:count])
        room = count
