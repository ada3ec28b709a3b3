"""The seam to the Zenoh binding (``eclipse-zenoh``): the one module of anodize that imports ``zenoh``.

The rest of the Zenoh transport uses the binding only through the functions and names
declared here, so that a binding release that moves them breaks this module only.
``zenoh`` is imported when this module is, through :func:`anodize._extras.import_extra`:
without the ``anodize[zenoh]`` extra that raises :class:`~anodize.errors.MissingExtraError`.

Every publisher of anodize's own traffic is reliable with congestion control Block: a
full transmission queue makes ``put`` wait (releasing the GIL) rather than drop, the
credits (:mod:`.flow`) keeping that wait short; Zenoh's reliability is per hop, so the
transport numbers its samples and sends again what a router lost (:mod:`.sender`).
"""

from __future__ import annotations

import contextlib
import json
import re
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..._extras import import_extra

if TYPE_CHECKING:
    from zenoh import LivelinessToken, Publisher, Sample, Session, Subscriber, ZError
    from zenoh.handlers import Handler
else:
    _zenoh = import_extra("zenoh", "zenoh", "the Zenoh transport")
    LivelinessToken, Publisher, Sample, Session = (_zenoh.LivelinessToken, _zenoh.Publisher, _zenoh.Sample,
                                                   _zenoh.Session)
    Subscriber, ZError = _zenoh.Subscriber, _zenoh.ZError

__all__ = ["reason", "open_session", "publisher", "local_publisher", "subscribe", "subscribe_pulled",
           "token", "watch_tokens", "is_delete", "payload_of",
           "attachment_of", "key_of", "undeclare", "close", "LivelinessToken", "Publisher", "Sample", "Session",
           "Subscriber", "ZError"]


_RUST_PLACE = re.compile(r"\s*at /\S+\.rs:\d+\.?")  # where in zenoh's Rust sources an error was raised


def reason(error: BaseException) -> str:
    """A Zenoh error's message for a user: without the Rust source places Zenoh appends to it."""
    return _RUST_PLACE.sub("", str(error)).strip()


def open_session(config: dict[str, Any]) -> Session:
    """A Zenoh session with ``config`` (JSON as :func:`.settings.session_config` makes it).

    Raises:
        ZError: the configuration is refused, or (a client) no router answered in time.
    """
    import zenoh

    return zenoh.open(zenoh.Config.from_json5(json.dumps(config)))


def publisher(session: Session, key: str, reliable: bool = True, block: bool = True, cache: int = 0,
              express: bool = False) -> Publisher:
    """A reliable publisher on ``key`` whose ``put`` waits when the network is congested (a ROS
    topic's may be best effort, or drop under congestion, as rmw_zenoh's are). With ``cache``, an
    advanced publisher that keeps its last ``cache`` samples for subscribers that join later
    (a transient-local ROS topic, as rmw_zenoh declares one: detectable, with miss detection when
    reliable); it has the same ``put``. ``express``: each put is sent at once, never held back to
    be batched with the next (latency, at the cost of a stream's rate)."""
    import zenoh

    congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
    reliability = zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT
    if cache:
        import zenoh.ext

        miss = zenoh.ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=0.5) if reliable else None
        advanced: Publisher = zenoh.ext.declare_advanced_publisher(  # type: ignore[assignment]
            session, key, congestion_control=congestion, reliability=reliability,
            cache=zenoh.ext.CacheConfig(max_samples=cache), sample_miss_detection=miss, publisher_detection=True)
        return advanced
    return session.declare_publisher(key, congestion_control=congestion, reliability=reliability, express=express)


def local_publisher(session: Session, key: str) -> Publisher:
    """A publisher whose puts reach only this session's own subscribers (never the network)."""
    import zenoh

    return session.declare_publisher(key, allowed_destination=zenoh.Locality.SESSION_LOCAL)


def subscribe(session: Session, key: str, callback: Callable[[Sample], None]) -> Subscriber[None]:
    """Call ``callback`` (on one of Zenoh's threads) with every sample put on ``key``."""
    return session.declare_subscriber(key, callback)


def subscribe_pulled(session: Session, key: str, capacity: int) -> Subscriber[Handler[Sample]]:
    """A subscriber whose samples wait in a ring of ``capacity`` (Zenoh's thread never blocks on it,
    nor takes the GIL: the oldest is dropped when it is full), read with ``try_recv()`` and ``recv()``
    (which waits, releasing the GIL). One thread at a time may use it (PyO3 raises otherwise)."""
    import zenoh

    return session.declare_subscriber(key, zenoh.handlers.RingChannel(capacity))


def token(session: Session, key: str) -> LivelinessToken:
    """Declare a liveliness token on ``key``: it vanishes for everyone when the session dies."""
    return session.liveliness().declare_token(key)


def watch_tokens(session: Session, key: str, callback: Callable[[Sample], None]) -> Subscriber[None]:
    """Call ``callback`` for every liveliness token matching ``key`` that is there now or appears
    later (a put), and every one that vanishes (a delete)."""
    return session.liveliness().declare_subscriber(key, callback, history=True)


def is_delete(sample: Sample) -> bool:
    """Whether a liveliness sample says a token vanished."""
    import zenoh

    return bool(sample.kind == zenoh.SampleKind.DELETE)


def payload_of(sample: Sample) -> bytes:
    """A sample's payload as bytes (one copy)."""
    return sample.payload.to_bytes()


def attachment_of(sample: Sample) -> bytes:
    """A sample's attachment as bytes (empty if it has none)."""
    attachment = sample.attachment
    return b"" if attachment is None else attachment.to_bytes()


def key_of(sample: Sample) -> str:
    """A sample's key expression as text."""
    return str(sample.key_expr)


def undeclare(entity: Publisher | Subscriber[Any] | LivelinessToken) -> None:
    """Withdraw a publisher, subscriber or token now (its peers see it gone); once more is harmless."""
    with contextlib.suppress(ZError):
        entity.undeclare()  # type: ignore[no-untyped-call]  # the binding's stub leaves it untyped


def close(session: Session) -> None:
    """Close a session: its tokens vanish for everyone at once; once more is harmless."""
    with contextlib.suppress(ZError):
        session.close()  # type: ignore[no-untyped-call]  # the binding's stub leaves it untyped
