"""Channels between groups over Eclipse Zenoh: ``transport = "zenoh"``.

Each group is its own process (as with ``transport="process"``) with one Zenoh session,
in peer mode (finding the others by scouting on a LAN, or through ``connect``) or client
mode (through one or more routers); channels inside a group stay queues, and every
channel between roles of different groups is the key expression
``anodize/<run id>/<token digest>/ch/<sender>/<receiver>``, with one publisher (in the
sender's group) and one subscriber (in the receiver's). The guarantees are DDS's
(:mod:`anodize._transport.dds`):

- **Nothing lost, duplicated or reordered**, across a router that restarts: Zenoh is
  reliable per hop only, so every sample is numbered; the receiver hands them on in
  order and drops duplicates and gaps, and its credits acknowledge what it received;
  the sender keeps what is not acknowledged (a window at most) and sends it again when
  the acknowledgement does not move for a while.
- **Back pressure** by credits (:mod:`.flow`): a window of samples and bytes; a
  receiver that falls behind holds bounded memory. Publishers use congestion control
  Block, so a put waits rather than drops.
- **Who may listen**: every key is under ``anodize/<run id>/<token digest>``; the token
  is a secret of the run (fresh when one host runs every group, else
  ``$ANODIZE_ZENOH_TOKEN``).
- **Who may speak**: every sample carries its number, its writer's id and its claim in
  its attachment (:mod:`.identity`); a receiver accepts only the writer chosen at the
  start barrier, others are dropped, counted and reported with their claim. Not
  security (see docs/guide/zenoh.md).
- **Failures**: each group declares ``.../alive/<group>/<incarnation>/<host>`` and each
  end of a channel its own liveliness token; Zenoh's lease is the run's ``lease``, so a
  dead or cut-off session's tokens vanish within about a lease, and a token gone for
  longer than the grace (lease + outage) fails its peer: a blocked receiver gets a
  :class:`PeerFailure`, a blocked sender a ``PeerFailedError``. A role that fails in a
  live process has a failure frame put after its last message.

The modules, one concept each: :mod:`.settings` (what a group needs, key expressions,
the Zenoh configuration), :mod:`.binding` (the only module that imports ``zenoh``),
:mod:`.identity` (attachments), :mod:`.flow` (credits), :mod:`.session` (a group's
session), :mod:`.peers` (liveliness tokens), :mod:`.sender`, :mod:`.receiver`,
:mod:`.barrier` (the start barrier), :mod:`.links` (the transport's
:class:`~anodize._transport.links.Links`). Importing this package does not import
``zenoh``, so ``import anodize`` works without the ``anodize[zenoh]`` extra.
"""

from __future__ import annotations

from .settings import MODES, TOKEN_ENV, StartBarrierError, ZenohSettings, key_chunk, session_config

__all__ = ["ZenohSettings", "StartBarrierError", "TOKEN_ENV", "MODES", "key_chunk", "session_config"]
