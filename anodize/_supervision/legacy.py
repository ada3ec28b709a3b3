"""The keyword forms ``System`` and ``System.run`` took before transports were values.

``System(g, transport="dds", domain=7, ros_topics={...})`` and ``run(liveness=...,
host=..., wait=..., record=..., live=...)`` still work for one release: each builds
the new values (:mod:`.transports`, :class:`.rosbridge.RosBridge`, channel taps) and
warns with a :class:`DeprecationWarning` that says what to write instead. They go in
the release after the one that deprecated them (docs/guide/transports.md).
"""

from __future__ import annotations

import dataclasses
import importlib
import os
import warnings
from collections.abc import Iterable, Mapping
from typing import Any

from ..errors import ConfigurationError
from ..taps import ChannelTap
from .rosbridge import RosBridge
from .transports import KINDS, Dds, Inproc, Processes, Transport

__all__ = ["legacy_system", "legacy_run", "legacy_taps"]

# The caller of System(...) or System.run(...): warn() is called from here, under the method.
_STACK = 4


def _deprecated(old: str, new: str) -> None:
    warnings.warn(f"{old} is deprecated and goes in the next release; write {new}", DeprecationWarning,
                  stacklevel=_STACK)


def legacy_system(transport: str, domain: int | None, run_id: str | None, ros_topics: Mapping[str, str] | None,
                  external: Iterable[str] | None, ros_distro: str | None,
                  ros_domain: int | None) -> tuple[Transport, RosBridge | None]:
    """The transport value and ROS bridge the old keywords of ``System(...)`` meant.

    Raises:
        ConfigurationError: an unknown transport, or a value a field refuses.
    """
    if transport not in KINDS:
        raise ConfigurationError(f"transport {transport!r}: expected one of {', '.join(KINDS)} "
                                 "(or a value: Inproc(), Processes(), Dds())")
    value: Transport
    if transport == "dds":
        value = Dds(domain=0 if domain is None else domain, run_id=run_id or "")
        shown = f"transport=Dds({_fields(value)})"
    else:
        if domain is not None or run_id is not None:
            # They only ever meant something on DDS; before, they were checked and ignored.
            Dds(domain=0 if domain is None else domain, run_id=run_id or "")
        value = Inproc() if transport == "inproc" else Processes()
        shown = f"transport={type(value).__name__}()"
    ros = None
    if ros_topics or external or ros_distro or ros_domain is not None:
        ros = RosBridge(topics=dict(ros_topics or {}), external=frozenset(external or ()), distro=ros_distro or "",
                        domain=ros_domain)
        shown += f", ros=RosBridge({_fields(ros)})"
    _deprecated(f"System(..., transport={transport!r}, ...) with DDS or ROS keywords" if transport == "dds" or ros
                else f"System(..., transport={transport!r})", f"System(..., {shown})")
    return value, ros


def legacy_run(transport: Transport, liveness: float | None, host: str | None, wait: float | None) -> Transport:
    """``transport`` with what the old keywords of ``System.run`` set (each of them only matters on
    some transports; elsewhere it is checked, as before, and has no effect).

    Raises:
        ConfigurationError: a value a field refuses.
    """
    given = {name: value for name, value in (("liveness", liveness), ("host", host), ("wait", wait))
             if value is not None}
    if not given:
        return transport
    if liveness is not None:  # checked as before, whatever the transport
        Processes(liveness=liveness)
    if host is not None or wait is not None:
        Dds(host=host, wait=30.0 if wait is None else wait)
    fields = {f.name for f in dataclasses.fields(transport)}
    changed = dataclasses.replace(transport, **{k: v for k, v in given.items() if k in fields})  # type: ignore[arg-type]
    idle = [k for k in given if k not in fields]
    _deprecated(f"System.run({', '.join(f'{k}=...' for k in given)})",
                f"the transport's fields: System(..., transport={type(changed).__name__}({_fields(changed)}))"
                + (f" ({', '.join(idle)}: no such field, no effect on {type(changed).__name__})" if idle else ""))
    return changed


def legacy_taps(record: str | os.PathLike[str] | None, live: ChannelTap | None) -> list[ChannelTap]:
    """The taps the old ``record=`` and ``live=`` of ``System.run`` meant (recording first, as before)."""
    taps: list[ChannelTap] = []
    if record is not None:
        # Supervision does not import anodize._recording (it sits above, behind the tap protocol); only
        # this deprecated keyword reaches up for it, by name, and it goes with the keyword.
        recording: Any = importlib.import_module("anodize._recording")
        taps.append(recording.Recording(record))
        _deprecated("System.run(record=path)", "System.run(taps=[anodize.Recording(path)])")
    if live is not None:
        taps.append(live)
        _deprecated("System.run(live=view)", "System.run(taps=[view])")
    return taps


def _fields(value: Any) -> str:
    """``domain=7, run_id='x'``: a value's fields that differ from their defaults."""
    shown = []
    for f in dataclasses.fields(value):
        current = getattr(value, f.name)
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        if current != default:
            shown.append(f"{f.name}={current!r}")
    return ", ".join(shown)
