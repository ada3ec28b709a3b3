"""The ``[zenoh]`` table of a system file: how the groups of a run on ``kind = "zenoh"`` reach each other.

::

    [transport]
    kind = "zenoh"                           # run_id, host, wait, liveness, lease, outage here
    lease = 1.0

    [zenoh]
    mode = "client"                          # "peer" (default) or "client"
    connect = ["tcp/10.0.0.1:7447"]          # Zenoh endpoints: routers (or peers) to connect to
    listen = []                              # endpoints to listen on (a peer that others connect to)
    scouting = true                          # peers look for each other by multicast on the LAN

    [zenoh.hosts.robot]                      # the groups of host "robot" (group(..., host="robot"))
    connect = ["tcp/192.168.1.1:7447"]       # behind another router; unset keys are [zenoh]'s

    [zenoh.tls]                              # TLS on every link (every endpoint is then tls/...)
    root_ca = "certs/ca.pem"                 # paths relative to the system file, each host its own files
    certificate = "certs/host.pem"           # with private_key: to listen, and (mutual) to connect
    private_key = "certs/host.key"
    mutual = false                           # true: whoever connects shows a certificate root_ca signed

The table is read even when ``[transport]`` names another kind, so that
``anodize run FILE --transport zenoh`` finds it.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .._transport.zenoh.settings import ZenohTls
from ..errors import ConfigurationError
from .config_error import ConfigError

__all__ = ["ZENOH_KEYS", "read_zenoh_table"]

ZENOH_KEYS = ("mode", "connect", "listen", "scouting", "hosts", "tls")  # the fields of Zenoh that [zenoh] gives
_HOST_KEYS = ("mode", "connect", "listen")
_TLS_KEYS = ("root_ca", "certificate", "private_key", "mutual")
_ENDPOINT = re.compile(r"[a-z0-9]+/[^\s#?]+(#\S*)?")


def read_zenoh_table(table: Any, error: Callable[[str, str], ConfigError],
                     directory: Path = Path(".")) -> dict[str, Any]:
    """The :class:`~anodize.Zenoh` fields ``[zenoh]`` gives (empty without the table); the paths of
    ``[zenoh.tls]`` are taken relative to ``directory`` (the system file's).

    Raises:
        ConfigError: (made by ``error(key, problem)``) an unknown key, a mode other than peer or
            client, endpoints that are not an array of ``"proto/address"`` strings, a ``[zenoh.tls]``
            that is not one.
    """
    if table is None:
        return {}
    if not isinstance(table, dict):
        raise error("zenoh", f"expected a table [zenoh], got {table!r}")
    _known(table, ZENOH_KEYS, "zenoh", error)
    found: dict[str, Any] = {}
    if "mode" in table:
        found["mode"] = _mode(table["mode"], "zenoh.mode", error)
    for key in ("connect", "listen"):
        if key in table:
            found[key] = _endpoints(table[key], f"zenoh.{key}", error)
    if "scouting" in table:
        if not isinstance(table["scouting"], bool):
            raise error("zenoh.scouting", f"expected true or false, got {table['scouting']!r}")
        found["scouting"] = table["scouting"]
    hosts = table.get("hosts", {})
    if not isinstance(hosts, dict):
        raise error("zenoh.hosts", f"expected tables such as [zenoh.hosts.robot], got {hosts!r}")
    entries = []
    for host, given in hosts.items():
        where = f"zenoh.hosts.{host}"
        if not host.isidentifier():
            raise error(where, f"expected a host name such as robot or base_1, got {host!r}")
        if not isinstance(given, dict):
            raise error(where, f"expected a table such as {{ connect = [\"tcp/10.0.0.1:7447\"] }}, got {given!r}")
        _known(given, _HOST_KEYS, where, error)
        mode = _mode(given["mode"], f"{where}.mode", error) if "mode" in given else found.get("mode", "peer")
        connect = (_endpoints(given["connect"], f"{where}.connect", error) if "connect" in given
                   else found.get("connect", ()))
        listen = (_endpoints(given["listen"], f"{where}.listen", error) if "listen" in given
                  else found.get("listen", ()))
        if mode == "client" and not connect:
            raise error(where, "mode \"client\": expected the endpoints of one or more routers in connect, got none")
        entries.append((host, mode, connect, listen))
    if entries:
        found["hosts"] = tuple(entries)
    if "tls" in table:
        found["tls"] = _tls(table["tls"], error, directory)
    return found


def _tls(table: Any, error: Callable[[str, str], ConfigError], directory: Path) -> ZenohTls:
    if not isinstance(table, dict):
        raise error("zenoh.tls", f"expected a table [zenoh.tls] such as {{ root_ca = \"certs/ca.pem\" }}, "
                                 f"got {table!r}")
    _known(table, _TLS_KEYS, "zenoh.tls", error)
    paths = {}
    for key in ("root_ca", "certificate", "private_key"):
        if key in table:
            if not isinstance(table[key], str) or not table[key]:
                raise error(f"zenoh.tls.{key}", f"expected the path of a PEM file, got {table[key]!r}")
            paths[key] = os.path.abspath(directory / table[key])
    try:
        return ZenohTls(**paths, mutual=table.get("mutual", False))
    except ConfigurationError as problem:
        key = next((f"zenoh.tls.{k}" for k in _TLS_KEYS if f"tls {k}:" in str(problem)), "zenoh.tls")
        raise error(key, str(problem).split(": ", 1)[1]) from None


def _known(table: dict[str, Any], allowed: tuple[str, ...], prefix: str,
           error: Callable[[str, str], ConfigError]) -> None:
    for key in table:
        if key not in allowed:
            raise error(f"{prefix}.{key}", f"unknown key; expected one of {', '.join(sorted(allowed))}")


def _mode(value: Any, key: str, error: Callable[[str, str], ConfigError]) -> str:
    if value not in ("peer", "client"):
        raise error(key, f"expected \"peer\" or \"client\", got {value!r}")
    return str(value)


def _endpoints(value: Any, key: str, error: Callable[[str, str], ConfigError]) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(e, str) for e in value):
        raise error(key, f"expected an array of Zenoh endpoints such as [\"tcp/10.0.0.1:7447\"], got {value!r}")
    for endpoint in value:
        if not _ENDPOINT.fullmatch(endpoint):
            raise error(key, f"expected Zenoh endpoints such as \"tcp/10.0.0.1:7447\" (protocol/address), "
                             f"got {endpoint!r}")
    return tuple(value)
