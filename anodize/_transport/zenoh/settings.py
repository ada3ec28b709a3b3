"""What a group's process needs to join its run on Zenoh, the key expressions derived from it, and
the Zenoh configuration of its session."""

from __future__ import annotations

import hashlib
import os
import re
import secrets
import socket
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

from ...errors import ConfigurationError
from ..links import SplitBrainError, StartBarrierError
from ..ros_lanes import RosSettings

__all__ = ["ZenohSettings", "ZenohTls", "SECURE_PROTOCOLS", "tls_hint", "TOKEN_ENV", "StartBarrierError",
           "SplitBrainError", "MODES", "session_config", "tls_config", "key_chunk", "run_token", "supervisor_settings",
           "loopback_endpoint"]

TOKEN_ENV = "ANODIZE_ZENOH_TOKEN"  # a run's secret token, the same on every host of the run
MODES = ("peer", "client")
SECURE_PROTOCOLS = ("tls/", "quic/")  # Zenoh's links that take their keys from transport/link/tls


@dataclass(frozen=True)
class ZenohTls:
    """TLS on a Zenoh run's links: what crosses a site network or a cellular link is encrypted,
    and a host talks only to routers and peers whose certificate a known authority signed. Every
    endpoint is then ``tls/ADDRESS:PORT``. Each host reads its own files (PEM) at these paths.

    Args:
        root_ca: the certificate of the authority that signs the certificates of the routers and
            peers this host connects to (and, with ``mutual``, of those that connect to it).
        certificate: this host's certificate; with ``private_key``, needed to listen on a
            ``tls/`` endpoint (a peer, a router) and, with ``mutual``, to connect. It must name
            the address others reach it at (``tls/robot.site:7447``: robot.site; an IP address
            as an IP entry), as Zenoh checks the name on connecting.
        private_key: the key of ``certificate``.
        mutual: the listening side asks whoever connects for a certificate ``root_ca`` signed,
            so that only holders of one can join the run's network (mutual TLS).

    Raises:
        ConfigurationError: a path that is not a string ("": not given), a certificate without its
            key (or the other way round), ``mutual`` without all three files, or no file at all.
    """

    root_ca: str = ""
    certificate: str = ""
    private_key: str = ""
    mutual: bool = False

    def __post_init__(self) -> None:
        for name in ("root_ca", "certificate", "private_key"):
            value = getattr(self, name)
            if not isinstance(value, str) or "\0" in value:
                raise ConfigurationError(f"Zenoh tls {name}: expected the path of a PEM file, got {value!r}")
        if not isinstance(self.mutual, bool):
            raise ConfigurationError(f"Zenoh tls mutual: expected true or false, got {self.mutual!r}")
        if bool(self.certificate) != bool(self.private_key):
            given, missing = ("certificate", "private_key") if self.certificate else ("private_key", "certificate")
            raise ConfigurationError(f"Zenoh tls: {given} is given but not {missing}: a certificate goes with its key")
        if self.mutual and not (self.root_ca and self.certificate):
            raise ConfigurationError("Zenoh tls mutual: expected root_ca, certificate and private_key (each side "
                                     "shows its certificate and checks the other's against root_ca)")
        if not (self.root_ca or self.certificate):
            raise ConfigurationError("Zenoh tls: expected root_ca (to connect), or certificate and private_key "
                                     "(to listen), or all three")

    def files(self) -> dict[str, str]:
        """The files given, by the name of their setting."""
        return {name: path for name, path in (("root_ca", self.root_ca), ("certificate", self.certificate),
                                              ("private_key", self.private_key)) if path}

    def missing(self) -> str | None:
        """What is wrong with the files on this host (one not there, or not readable), or None."""
        for name, path in self.files().items():
            try:
                with open(path, "rb") as file:
                    file.read(1)
            except OSError as error:
                return f"Zenoh tls {name}: cannot read {path}: {error.strerror or error}"
        return None


@dataclass(frozen=True)
class ZenohSettings:
    """What a group's process needs to join its run on Zenoh (picklable, in the group's spec).

    Attributes:
        mode: ``"peer"`` (finds the others by scouting, or through ``connect``) or ``"client"``
            (talks only to the routers of ``connect``).
        connect: Zenoh endpoints to connect to (``"tcp/10.0.0.1:7447"``).
        listen: Zenoh endpoints to listen on (a peer that others connect to).
        run_id: keeps two runs of the same system apart (part of every key expression).
        host: the host this group runs on (for messages and identities).
        group_of: role -> group, for every role of the system.
        host_of: group -> host, for every group of the system.
        lease: seconds of Zenoh's link lease: a peer whose session dies, freezes or is cut off
            is noticed within about one lease (its liveliness tokens vanish).
        outage: seconds more a peer's tokens may stay gone before it is failed: a router that
            restarts within it is ridden through (0: a peer gone for a lease is failed).
        wait: seconds the start barrier waits for every peer (and a client for its router).
        scouting: whether a peer looks for the others by multicast scouting on its LAN (off
            where the endpoints are given, as in tests, so that runs do not meet by accident).
        token: a secret of this run (see :attr:`prefix`).
        tls: TLS on the links (every endpoint is then ``tls/...``), or None.
        ros: the run's ROS topics (``[ros.topics]``), published as rmw_zenoh does (:mod:`.ros_topics`).
    """

    mode: str
    run_id: str
    host: str
    group_of: Mapping[str, str]
    host_of: Mapping[str, str]
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    lease: float = 1.0
    outage: float = 0.0
    wait: float = 30.0
    scouting: bool = True
    token: str = field(default="", repr=False)
    ros: RosSettings | None = None
    tls: ZenohTls | None = None
    LINKS: ClassVar[str] = "anodize._transport.zenoh.links:ZenohLinks"  # its links (the group spec's seam)

    @property
    def digest(self) -> str:
        """The run's token as the key expressions carry it: a digest, not the token itself."""
        return hashlib.sha256(f"{self.run_id}/{self.token}".encode()).hexdigest()[:16]

    @property
    def prefix(self) -> str:
        """The key prefix of every key expression of the run: ``anodize/<run id>/<token digest>``.
        A subscriber matches only keys under it, so other runs' traffic never reaches ours;
        anyone who can read the run's traffic can copy it (it is not security)."""
        return f"anodize/{key_chunk(self.run_id)}/{self.digest}"

    @property
    def claim_run(self) -> str:
        """The run as identities name it: the run id and the token's digest."""
        return f"{self.run_id}/{self.digest}"

    def channel_key(self, sender: str, receiver: str) -> str:
        """Where a channel's samples travel."""
        return f"{self.prefix}/ch/{key_chunk(sender)}/{key_chunk(receiver)}"

    def credit_key(self, sender: str, receiver: str) -> str:
        """Where a channel's receiver says how far it has got (credits and acknowledgements)."""
        return f"{self.prefix}/credit/{key_chunk(sender)}/{key_chunk(receiver)}"

    def end_key(self, end: str, sender: str, receiver: str, group: str, incarnation: int, ident: str) -> str:
        """The liveliness token of one end (``"writer"`` or ``"reader"``) of a channel."""
        return (f"{self.prefix}/{end}/{key_chunk(sender)}/{key_chunk(receiver)}/{key_chunk(group)}/"
                f"{incarnation}/{ident}")

    def alive_key(self, group: str, incarnation: int, host: str) -> str:
        """The liveliness token of a group's process: ``.../alive/<group>/<incarnation>/<host>``."""
        return f"{self.prefix}/alive/{key_chunk(group)}/{incarnation}/{key_chunk(host)}"

    @property
    def supervisors_key(self) -> str:
        """Where the run's supervisors speak to each other."""
        return f"{self.prefix}/supervisors"

    def where(self, role: str) -> str:
        """Where ``role`` runs, for messages."""
        group = self.group_of.get(role, "?")
        return f"group {group} on host {self.host_of.get(group, '?')}"

    def is_external(self, role: str) -> bool:
        """Whether ``role`` is played outside anodize, by a ROS 2 node on rmw_zenoh."""
        return self.ros is not None and role in self.ros.external


def key_chunk(text: str) -> str:
    """``text`` as one chunk of a key expression: no ``/``, wildcards or other reserved characters."""
    return re.sub(r"[^A-Za-z0-9_.-]", lambda m: f"_{ord(m.group()):x}_", text) or "_"


def session_config(settings: ZenohSettings) -> dict[str, Any]:
    """The Zenoh configuration (as JSON) of a group's session.

    The lease is Zenoh's link lease (``transport/link/tx/lease``, with four keep-alives a
    lease), so a peer that dies is dropped, and its liveliness tokens vanish, within about
    one lease. Connections are retried (every 0.2 s at first, at most every second), so a
    client finds its router again after the router restarts; a client waits up to ``wait``
    for its router at the start. With TLS, :func:`tls_config`.
    """
    retry = {"period_init_ms": 200, "period_max_ms": 1000, "period_increase_factor": 2.0}
    client = settings.mode == "client"
    link: dict[str, Any] = {"tx": {"lease": max(100, int(settings.lease * 1000)), "keep_alive": 4}}
    if settings.tls is not None:
        link["tls"] = tls_config(settings.tls)
    return {
        "mode": settings.mode,
        "connect": {"endpoints": list(settings.connect), "retry": retry,
                    "timeout_ms": int(settings.wait * 1000) if client else -1,
                    "exit_on_failure": client},
        # No listen endpoints given: Zenoh's default (a peer listens on a free TCP port, a client on none);
        # but with TLS, nothing listens in the clear (a supervisor's peer session listens nowhere).
        **({"listen": {"endpoints": list(settings.listen)}} if settings.listen or settings.tls else {}),
        "scouting": {"multicast": {"enabled": settings.scouting and not client},
                     "gossip": {"enabled": True}},
        "transport": {"link": link},
    }


def tls_hint(settings: ZenohSettings) -> str:
    """What to ask about TLS when a session of ``settings`` could not open or reach anyone ("" without TLS)."""
    tls = settings.tls
    if tls is None:
        return ""
    hint = (f"; over TLS, does the certificate of what it connects to name the address connected to, signed "
            f"by {tls.root_ca or 'an authority this host trusts (no root_ca given)'}")
    if tls.mutual:
        return hint + ", and does it accept this host's certificate (mutual TLS)?"
    return hint + "? (A router that asks for mutual TLS turns away a host that shows no certificate.)"


def tls_config(tls: ZenohTls) -> dict[str, Any]:
    """Zenoh's ``transport/link/tls`` for ``tls``: the one certificate and key serve both for
    listening and, with mutual TLS, for connecting; Zenoh checks the name the certificate of
    whatever it connects to gives against the endpoint's address (its default, kept)."""
    config: dict[str, Any] = {"enable_mtls": tls.mutual}
    if tls.root_ca:
        config["root_ca_certificate"] = tls.root_ca
    if tls.certificate:
        config |= {"listen_certificate": tls.certificate, "listen_private_key": tls.private_key}
        if tls.mutual:
            config |= {"connect_certificate": tls.certificate, "connect_private_key": tls.private_key}
    return config


_TOKEN = re.compile(r"[A-Za-z0-9_.-]{8,128}")


def run_token(several_hosts: bool) -> str:
    """The run's token (:attr:`ZenohSettings.token`): ``$ANODIZE_ZENOH_TOKEN`` if set; else a fresh
    random one when this host runs every group, and none ("") for a run over several hosts.

    Raises:
        ConfigurationError: the variable is set to something that is not a token.
    """
    given = os.environ.get(TOKEN_ENV, "")
    if given:
        if not _TOKEN.fullmatch(given):  # the value is a secret: say what is wrong, not what it is
            raise ConfigurationError(f"{TOKEN_ENV}: expected 8 to 128 letters, digits, '_', '.' or '-', got "
                                     f"{len(given)} characters" + ("" if given.isprintable() else
                                                                   ", some not printable"))
        return given
    return "" if several_hosts else secrets.token_hex(8)


def supervisor_settings(settings: ZenohSettings) -> ZenohSettings:
    """The settings of a host's supervisor's session: its groups' (``settings``), but listening on
    nothing (the host's listen endpoints are its group's) and, a peer, connecting to them too, so
    that supervisors meet where their groups do."""
    connect = settings.connect
    if settings.mode == "peer":
        connect += tuple(_on_loopback(endpoint) for endpoint in settings.listen)
    return replace(settings, listen=(), connect=connect)


def _on_loopback(endpoint: str) -> str:
    """An endpoint listening on every address (``0.0.0.0``, ``[::]``), as reached from its own host."""
    return endpoint.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:")


def loopback_endpoint() -> str:
    """A TCP endpoint on loopback with a port free now (the kernel's choice), for peers of one host to meet."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"
