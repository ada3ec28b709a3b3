"""Channels between groups as DDS topics on Cyclone DDS: ``transport="dds"``.

Each group is still its own process (as with ``transport="process"``); channels
inside it stay queues, and every channel between roles of different groups is
one DDS topic, ``anodize/<run id>/<sender>/<receiver>`` in the run's partition, with one writer (in the
sender's group) and one reader (in the receiver's). The groups may run on other
hosts: they find each other by DDS discovery on the run's domain.

- **Nothing lost, duplicated or reordered**: reliable, keep-all history on both
  ends. **Back pressure** by credits: the receiver tells the sender, on the
  channel's ``.../credit`` topic (keep-last 1), how many samples it has handed on
  to its role; the sender writes at most ``_WINDOW`` samples (and about
  ``_WINDOW_BYTES``) ahead of that, fewer than the reader's resource limit, so a
  receiver that falls behind holds bounded memory; otherwise the sender waits on
  the credit reader (in steps that look at failures and stops). The reader thus
  never rejects a sample; should it (a failure frame does not wait for credit),
  Cyclone's own reliability brings it again, and a write that finds no room is
  retried in short sleeps that release the GIL.
- **Raw bytes**: the topic type is ``anodize::Frame { sequence<octet> data; }``;
  frames of :mod:`anodize._transport.codec` are written as CDR built in :mod:`.frame` and
  taken as raw CDR, so a 900 KB array costs a copy, not the binding's element-by-element
  encoding.
- **Who may listen**: every endpoint on anodize's own topics is in the run's DDS
  partition, ``anodize/<run id>/<token>`` (the token a secret of the run: fresh
  when one host runs every group, else ``$ANODIZE_DDS_TOKEN``), so no endpoint of
  another run ever matches ours: none can hold a channel back or feed it. A reader
  that does match (subscribed to every partition) and holds writes back is named
  in the report. ROS 2 topics stay in the default partition, where ROS 2 looks.
- **Who may speak**: every writer carries its identity in its USER_DATA QoS (run
  id and token, group, incarnation, host, pid). A reader accepts samples only from
  the one writer of the expected group, chosen at the start barrier; samples from
  any other writer are dropped, counted and reported with the writer's GUID and
  claimed identity. An endpoint there before the run cannot claim a group (it
  cannot know the token); it is not security: anyone who reads the discovery
  traffic can copy the token (see docs/guide/dds.md).
- **Failures**: writers assert liveliness automatically with a lease of
  ``lease`` seconds and the participant's discovery lease is the same, so a group
  whose process dies, freezes or is cut off loses its writers and readers within
  about one lease; a blocked receiver then gets a :class:`PeerFailure`, a blocked
  sender a ``PeerFailedError``. A role that fails in a live process has a failure
  frame written after its last message, as with pipes.

The modules, one concept each: :mod:`.settings` (what a group needs to join, topic
names, Cyclone configuration), :mod:`.identity` (USER_DATA), :mod:`.flow` (credits),
:mod:`.qos` (the participant and QoS), :mod:`.frame` (the topic type, raw CDR),
:mod:`.sender`, :mod:`.receiver`, :mod:`.peers` and :mod:`.barrier` (the start
barrier), :mod:`.links` (the transport's :class:`~anodize._transport.links.Links`).
:mod:`.binding` is the only module that imports ``cyclonedds`` or touches its
private API; importing this package does not import it (the names that need the
binding are loaded on first use), so ``import anodize`` works without the
``anodize[dds]`` extra.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .flow import READER_SAMPLES
from .identity import identity_of, instance_handle, ros_userdata, userdata_fields
from .settings import DOMAIN_ENV, DdsSettings, StartBarrierError, participant_config, topic_name

if TYPE_CHECKING:
    from .binding import ANY_SAMPLE, userdata_of
    from .frame import Frame, cdr_sample, ros_sample
    from .links import DdsLinks
    from .receiver import DdsReceiver
    from .sender import DdsSender

__all__ = ["DdsSettings", "DdsLinks", "DdsSender", "DdsReceiver", "Frame", "topic_name", "identity_of",
           "participant_config", "DOMAIN_ENV", "StartBarrierError", "ANY_SAMPLE", "cdr_sample", "ros_sample",
           "instance_handle", "userdata_of", "userdata_fields", "ros_userdata", "READER_SAMPLES"]

# Names that need the binding, and the module of each: imported on first use, not with the package.
_NEEDS_BINDING = {"ANY_SAMPLE": "binding", "userdata_of": "binding", "Frame": "frame", "cdr_sample": "frame",
                  "ros_sample": "frame", "DdsLinks": "links", "DdsReceiver": "receiver", "DdsSender": "sender"}


def __getattr__(name: str) -> Any:
    module = _NEEDS_BINDING.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{module}"), name)
