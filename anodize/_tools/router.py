"""``anodize router``: a Zenoh router in this process, which the hosts of a run connect out to.

A router per site is how Zenoh crosses what multicast discovery does not (routers, NAT, a
cellular link): the hosts of a run in Zenoh's client mode connect to it (``[zenoh] connect``),
and it forwards each key expression to the sessions that subscribed to it. The router knows
nothing of anodize: what keeps runs apart is the runs' own key prefix and token, as on DDS.

It is configured as ROS 2's router for rmw_zenoh (``rmw_zenohd``) is by default: it listens on
``tcp/[::]:7447``; it neither scouts nor answers multicast scouting (the hosts name it in
their ``connect``, so a router started for a test or a demo never draws in the peers of
whoever else is on the network); its admin space is readable, not writable, so that Zenoh's
tools (and this module, for the ports it got) can ask it where it listens and whom it serves.
This module says what to print; ``cli.py`` prints it. It imports ``zenoh`` itself (through
``import_extra``), not through the transport's seam (``anodize/_transport/zenoh/binding.py``):
what it uses (a router's admin space, transport events) is the router's side of the binding,
which the transport never needs.
"""

from __future__ import annotations

import ipaddress
import json
import queue
import re
from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Any

from .._extras import import_extra
from .._transport.zenoh.settings import SECURE_PROTOCOLS, ZenohTls, tls_config
from ..errors import AnodizeError, ConfigurationError

__all__ = ["DEFAULT_LISTEN", "TLS_LISTEN", "ROUTER_PORT", "Router", "check_endpoint", "open_router", "tls_endpoints"]

ROUTER_PORT = 7447  # Zenoh's port for routers (zenohd's default)
DEFAULT_LISTEN = (f"tcp/[::]:{ROUTER_PORT}",)
TLS_LISTEN = f"tls/[::]:{ROUTER_PORT}"  # the default with TLS
FEATURE = "anodize router (a Zenoh router)"
_IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")  # PROTOCOL/ADDRESS:PORT
_OTHER_PROTOCOLS = ("unixsock-stream", "unixpipe", "serial", "vsock")  # PROTOCOL/something of their own
_HOST_NAME = re.compile(r"[A-Za-z0-9]([A-Za-z0-9.-]{0,252})")
_RUST_PLACE = re.compile(r"\s*at /\S+\.rs:\d+\.?")  # where in zenoh's sources an error was raised


def check_endpoint(endpoint: str) -> str | None:
    """What is wrong with a Zenoh endpoint such as ``tcp/10.0.0.1:7447``, or None.

    IP protocols (tcp, udp, tls, quic, ws) need ``ADDRESS:PORT``: an IPv4 address, an IPv6
    address in brackets, or a host name, and a port 0..65535 (0: any free port, for listening).
    """
    protocol, slash, rest = endpoint.partition("/")
    if not slash or not rest:
        return "expected PROTOCOL/ADDRESS:PORT such as tcp/0.0.0.0:7447"
    if protocol in _OTHER_PROTOCOLS:
        return None
    if protocol not in _IP_PROTOCOLS:
        return f"unknown protocol {protocol!r}: expected one of {', '.join(_IP_PROTOCOLS + _OTHER_PROTOCOLS)}"
    address = rest.split("?", 1)[0].split("#", 1)[0]  # Zenoh's ?metadata and #configuration
    host, colon, port = address.rpartition(":")
    if not colon or not port.isdigit() or not 0 <= int(port) <= 65535:
        return f"expected {protocol}/ADDRESS:PORT with a port 0..65535, such as {protocol}/0.0.0.0:7447"
    if host.startswith("[") and host.endswith("]"):
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            return f"{host} is not an IPv6 address"
        return None
    if ":" in host:
        return f"an IPv6 address goes in brackets: {protocol}/[{host}]:{port}"
    if not _HOST_NAME.fullmatch(host):
        return f"{host!r} is neither an IP address nor a host name"
    return None


@dataclass(frozen=True)
class _Connection:
    kind: str  # "client", "peer", "router"
    zid: str
    address: str  # the other end's locator, "" when unknown


class Router:
    """An open Zenoh router and what happened to it since (who connected, who left).

    Attributes:
        zid: the router's Zenoh id.
        locators: where it listens, each address spelt out (``tcp/[::]:7447`` becomes each of
            this host's addresses; a port 0 the port it got).
    """

    def __init__(self, zenoh: ModuleType, session: Any, listen: Sequence[str]) -> None:
        self._zenoh = zenoh
        self._session = session
        self._events: queue.SimpleQueue[tuple[bool, str, str]] = queue.SimpleQueue()
        self._known: dict[str, _Connection] = {}
        try:
            self.zid = str(session.zid())
            self.locators = self._ask_locators() or list(listen)
            self._listener = session.info.declare_transport_events_listener(self._on_transport, history=True)
        except BaseException:  # Ctrl-C while opening included: the router's port is not left bound
            session.close()
            raise

    def _ask_locators(self) -> list[str]:
        """Where the router listens, from its admin space (Zenoh resolves wildcards and port 0 there)."""
        for reply in self._session.get(f"@/{self.zid}/router", timeout=5.0):
            if reply.ok is not None:
                locators = json.loads(reply.ok.payload.to_string()).get("locators", [])
                return [str(locator) for locator in locators]
        return []

    def _on_transport(self, event: Any) -> None:
        # Zenoh's thread: only hand the event over (the reader looks up the rest in its own).
        opened = event.kind == self._zenoh.SampleKind.PUT
        self._events.put((opened, str(event.transport.zid), str(event.transport.whatami).lower()))

    def next_event(self, timeout: float) -> str | None:
        """A line on the next connection opened or closed (within ``timeout`` seconds), else None:
        ``client 1f0e9c2d connected from tcp/10.78.1.2:51234``."""
        try:
            opened, zid, kind = self._events.get(timeout=timeout)
        except queue.Empty:
            return None
        if opened:
            address = next((str(link.dst) for link in self._session.info.links() if str(link.zid) == zid), "")
            connection = self._known[zid] = _Connection(kind, zid, address)
            return f"{connection.kind} {zid[:8]} connected" + (f" from {address}" if address else "")
        connection = self._known.pop(zid, _Connection(kind, zid, ""))
        return f"{connection.kind} {zid[:8]} left" + (f" (was {connection.address})" if connection.address else "")

    def close(self) -> None:
        """Close the router: its clients see it gone (and reconnect to another, or retry)."""
        self._listener.undeclare()
        self._session.close()


def tls_endpoints(listen: Sequence[str] | None, connect: Sequence[str], tls: ZenohTls | None) -> list[str]:
    """Where a router with ``tls`` (or without) listens: ``listen``, or by default
    :data:`DEFAULT_LISTEN` (with TLS, :data:`TLS_LISTEN`).

    Raises:
        ConfigurationError: a ``tls/`` endpoint without TLS, an endpoint in the clear with it (whoever
            has no certificate could join there), or a side of TLS without its files.
    """
    if listen is None:
        listen = DEFAULT_LISTEN if tls is None else (TLS_LISTEN,)
    secure = [e for e in (*listen, *connect) if e.startswith(SECURE_PROTOCOLS)]
    if tls is None:
        if secure:
            raise ConfigurationError(f"{secure[0]}: a tls/ endpoint needs the router's TLS files (--tls-certificate "
                                     "and --tls-private-key to listen, --tls-root-ca to connect)")
        return list(listen)
    clear = [e for e in (*listen, *connect) if not e.startswith(SECURE_PROTOCOLS)]
    if clear:
        raise ConfigurationError(f"{clear[0]}: with TLS, every endpoint of the router is tls/ (else whoever has no "
                                 "certificate could join in the clear)")
    if listen and not tls.certificate:
        raise ConfigurationError("to listen on a tls/ endpoint, the router needs --tls-certificate and "
                                 "--tls-private-key")
    if connect and not tls.root_ca:
        raise ConfigurationError("to connect to a tls/ endpoint, the router needs --tls-root-ca (the authority that "
                                 "signs the other router's certificate)")
    return list(listen)


def open_router(listen: Sequence[str] | None = None, connect: Sequence[str] = (),
                tls: ZenohTls | None = None) -> Router:
    """Open a Zenoh router listening on ``listen`` and connecting to the routers at ``connect``
    (each retried until it answers, as Zenoh's routers do); by default it listens on
    :data:`DEFAULT_LISTEN`. With ``tls``, every endpoint is ``tls/``, the default :data:`TLS_LISTEN`.

    Raises:
        MissingExtraError: the ``zenoh`` extra is not installed.
        ConfigurationError: an endpoint that is not one (:func:`check_endpoint`; the command checks
            them first, as a usage error).
        AnodizeError: Zenoh could not open the router (e.g. an address this host does not have).
    """
    for option, endpoints in (("--listen", listen or ()), ("--connect", connect)):
        for endpoint in endpoints:
            problem = check_endpoint(endpoint)
            if problem is not None:
                raise ConfigurationError(f"{option} {endpoint}: {problem}")
    listen = tls_endpoints(listen, connect, tls)
    problem = tls.missing() if tls is not None else None
    if problem is not None:
        raise ConfigurationError(problem)
    zenoh = import_extra("zenoh", "zenoh", FEATURE)
    settings: list[tuple[str, object]] = [
        ("mode", "router"), ("listen/endpoints", list(listen)), ("connect/endpoints", list(connect)),
        ("scouting/multicast/enabled", False),
        ("adminspace", {"enabled": True, "permissions": {"read": True, "write": False}})]
    if tls is not None:
        settings.append(("transport/link/tls", tls_config(tls)))
    try:  # Zenoh reads the endpoints' ?metadata and #configuration, at either step
        config = zenoh.Config()
        for key, value in settings:
            config.insert_json5(key, json.dumps(value))
        session = zenoh.open(config)
    except zenoh.ZError as error:
        raise AnodizeError(f"cannot open a Zenoh router listening on {', '.join(listen)}"
                          f"{' and connecting to ' + ', '.join(connect) if connect else ''}: "
                          f"{_RUST_PLACE.sub('', str(error)).strip()}") from None
    return Router(zenoh, session, listen)
