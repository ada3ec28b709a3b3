"""What an endpoint has done so far, as one read-only record."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

__all__ = ["EndpointStatistics", "ConstraintCheck"]


def _frozen(counts: Mapping[str, int]) -> Mapping[str, int]:
    return MappingProxyType(dict(counts))


@dataclass(frozen=True, slots=True)
class ConstraintCheck:
    """How one constrained interaction fared at one endpoint.

    Attributes:
        checked: how many times its constraints were checked (one per send or receive).
        closest_ns: the smallest margin seen to a time bound (``within``, ``every +- jitter``),
            in nanoseconds; negative if it was missed; None if it has no time bound.
        timeouts: how many times its deadline passed and the receiver took ``else timeout``
            (not a miss: the protocol's own way on; not counted in ``closest_ns``).
    """

    checked: int = 0
    closest_ns: int | None = None
    timeouts: int = 0

    def joined(self, other: ConstraintCheck) -> ConstraintCheck:
        """Both records as one: counts summed, the closer margin."""
        margins = [m for m in (self.closest_ns, other.closest_ns) if m is not None]
        return ConstraintCheck(self.checked + other.checked, min(margins) if margins else None,
                               self.timeouts + other.timeouts)


@dataclass(frozen=True)
class EndpointStatistics:
    """Per peer, what one endpoint (with its parallel branches) has sent, received and seen wait.

    ``sent`` and ``received`` count messages; ``high_water`` is the most messages that waited
    at once in the channel to that peer, where the transport can tell. ``constraints`` holds,
    per constrained interaction (keyed by its local action and constraints, e.g.
    ``!Move(cmd) every 20ms +- 2ms``), how often it was checked and how close it came to its
    time bound (:class:`ConstraintCheck`). The mappings are
    read-only copies: a record never changes after :meth:`anodize.Endpoint.statistics`
    returns it.
    """

    sent: Mapping[str, int] = field(default_factory=dict)
    received: Mapping[str, int] = field(default_factory=dict)
    high_water: Mapping[str, int] = field(default_factory=dict)
    constraints: Mapping[str, ConstraintCheck] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # Copied into read-only views, so the endpoint's live counters never leak out.
        for name in ("sent", "received", "high_water"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        object.__setattr__(self, "constraints", MappingProxyType(dict(self.constraints)))

    @classmethod
    def combined(cls, own: EndpointStatistics, branches: Iterable[EndpointStatistics]) -> EndpointStatistics:
        """``own`` with its branches' records added: counts summed, high-water marks the maximum."""
        sent, received, high_water = dict(own.sent), dict(own.received), dict(own.high_water)
        constraints = dict(own.constraints)
        for branch in branches:
            for peer, n in branch.sent.items():
                sent[peer] = sent.get(peer, 0) + n
            for peer, n in branch.received.items():
                received[peer] = received.get(peer, 0) + n
            for peer, n in branch.high_water.items():
                high_water[peer] = max(high_water.get(peer, 0), n)
            for key, check in branch.constraints.items():
                known = constraints.get(key)
                constraints[key] = check if known is None else known.joined(check)
        return cls(sent, received, high_water, constraints)

    def __repr__(self) -> str:
        return (f"EndpointStatistics(sent={dict(self.sent)!r}, received={dict(self.received)!r}, "
                f"high_water={dict(self.high_water)!r}"
                + (f", constraints={dict(self.constraints)!r})" if self.constraints else ")"))
